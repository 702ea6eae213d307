// Candidate effects of the sim-to-real gap diagnosis: physical extensions of the cell model
// (through the CellEffect hook) that the nominal model leaves out, each with a few parameters,
// an "off" value that gives back the nominal model bit for bit, and a plausible range. Plus two
// effects that are not candidates (the data generator plants them to check that the diagnosis
// answers "unexplained"). Equations, ranges and signatures: doc/gap_effects.md.
#pragma once

#include <map>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "nursing_bed/core/physics/basic_effects.h"
#include "nursing_bed/core/physics/cell_effect.h"

namespace nursing_bed {

/// One parameter of an effect.
struct EffectParamSpec {
  std::string name;         ///< canonical key, SI unit suffix (e.g. "leak_area_m2")
  std::string unit;         ///< unit for people ("m^2", "W/(m^2 K)", "-")
  std::string description;  ///< meaning
  double off_value = 0.0;   ///< value of the nominal model (see EffectSpec::switch_param)
  /// Plausible range [lo, hi] for drawing and fitting. With `symmetric`, the plausible values
  /// are lo <= |x| <= hi of either sign (0 < lo < hi).
  double lo = 0.0, hi = 0.0;
  bool log_scale = false;  ///< draw/fit on a log scale (lo > 0)
  bool symmetric = false;
  /// Admissible range: what makeEffect() accepts (physically meaningful; contains the off value
  /// and the plausible range).
  double min_value = 0.0, max_value = 0.0;
};

/// One effect of the catalogue.
struct EffectSpec {
  std::string name;         ///< canonical name (doc/formats/gap_report.md)
  bool candidate = true;    ///< false: only the data generator plants it (never fitted)
  std::string description;  ///< what it is, one line
  std::string signature;    ///< the signature it leaves in a run, one line
  /// Parameter that alone turns the effect off at its off value (it then carries no state and
  /// adds nothing: the nominal model bit for bit); empty when every parameter must be at its
  /// off value (inflow_bias).
  std::string switch_param;
  std::vector<EffectParamSpec> params;
  /// The cell structure it assumes (CellParams::structure_type), empty for any: the diagnosis
  /// does not fit it on another structure and says so.
  std::string structure;
  /// A channel distortion (distortions.h): the channel it distorts and the kind ("gain+offset"
  /// for inflow_bias); both empty for a physical effect.
  std::string channel;
  std::string kind;

  /// Every parameter at its off value.
  std::map<std::string, double> offParams() const;
  /// The parameter of that name, or null.
  const EffectParamSpec* param(const std::string& name) const;
};

/// The entry of a catalogue (effects, calibrated parameters) named `name`; throws
/// std::invalid_argument "unknown KIND 'name' (known: ...)" otherwise.
template <typename Entry>
const Entry& catalogEntry(const std::vector<Entry>& catalog, const std::string& name, const std::string& kind) {
  for (const auto& e : catalog)
    if (e.name == name) return e;
  std::string known;
  for (const auto& e : catalog) known += (known.empty() ? "" : ", ") + e.name;
  throw std::invalid_argument("unknown " + kind + " '" + name + "' (known: " + known + ")");
}

/// The seven candidates, then the non-candidates ambient_drift, pressure_offset_drift,
/// plate_quadratic_drag and power_leak.
/// Catalogue order is also the order in which effects compose (see sortEffectsForModel()):
/// heat_transfer, leak, membrane_viscoelasticity, pressure_sensor_lag, supply_line,
/// inflow_bias, plate_friction, ambient_drift, pressure_offset_drift, plate_quadratic_drag,
/// power_leak.
const std::vector<EffectSpec>& effectCatalog();
/// Catalogue entry by name, of this catalogue, of the channel distortions' (distortions.h) or
/// of the discovery's dictionary (discovery_terms.h);
/// throws std::invalid_argument naming the known effects otherwise.
const EffectSpec& effectSpec(const std::string& name);
/// Names of the candidate effects, catalogue order.
std::vector<std::string> candidateEffectNames();

/**
 * Builds an effect from its catalogue name and parameters. Every parameter of the effect must
 * be given; throws std::invalid_argument naming the effect and the parameter for an unknown
 * effect, an unknown or missing parameter, or a value that is not finite or lies outside the
 * admissible range. An effect whose parameters switch it off carries no state and changes
 * nothing (bit-identical trajectories).
 */
CellEffectPtr makeEffect(const std::string& name, const std::map<std::string, double>& params);

/// Sorts effects into catalogue order (stable; effects not in the catalogue go last). Add
/// effects to a CellModel in this order: inflow_bias must read the flow meter after
/// supply_line has moved it upstream of the line (see the conventions below).
void sortEffectsForModel(std::vector<CellEffectPtr>* effects);

/// Parameters drawn uniformly within the plausible range (log-uniform where flagged; symmetric
/// ranges get a random sign). Throws std::invalid_argument for an unknown effect.
std::map<std::string, double> randomEffectParams(const std::string& name, std::mt19937& rng);

/// "name(p=v, ...)" for logs and reports.
std::string describeEffect(const std::string& name, const std::map<std::string, double>& params);

// ---- the effects (makeEffect() builds them; usable directly too) ---------------------------
//
// Conventions shared by all:
//  - measure(): an effect adds its own deviation to what the sensors report (pressure reading
//    += p_read - p_true, ...), so that several effects compose whatever their order. The one
//    exception is inflow_bias, which scales the flow reading as the others left it: it must
//    come after supply_line (catalogue order; sortEffectsForModel()).
//  - States that are pressures are stored as absolute pressure in units of 100 kPa, so that the
//    cell model's error control (relative tolerance on |x| + 1e-3) treats them like the cell's
//    own gas (about 10 Pa), not like a 1e-3 absolute floor.

/// Standard-linear-solid branch on the film: internal stretch lambda_v with
/// d(lambda_v)/dt = (lambda - lambda_v) / tau, and an overstress on the film's shape
/// coordinate g (dW/dlambda(lambda) - dW/dlambda(lambda_v)). Instantaneous film stiffness
/// (1 + g) W'', long-term W''. Assumes the cell's structure is the PillowStructure of
/// CellParams::structure (the default), whose shape coordinate 0 is the film stretch; it
/// takes that structure's elastic force at lambda_v once per call. g = 0: off (no state).
class MembraneViscoelasticityEffect : public CellEffect {
 public:
  MembraneViscoelasticityEffect(double relaxation_time_s, double relative_stiffness)
      : relaxation_time_s_(relaxation_time_s), relative_stiffness_(relative_stiffness) {}
  std::string name() const override { return "membrane_viscoelasticity"; }
  std::map<std::string, double> parameters() const override;
  int stateSize() const override { return relative_stiffness_ != 0.0 ? 1 : 0; }
  void initialState(const CellParams& params, const CellVariables& cell, double* state) const override;
  bool readsValveFlows() const override { return false; }
  void contribute(const CellParams& params, const CellVariables& cell, const double* state, EffectTerms* terms,
                  double* state_rate) const override;

 private:
  double relaxation_time_s_;
  double relative_stiffness_;
};

/// Flow meter error: it reads (1 + k) q_true + b. Prescribed (metered) inflow: the true flow
/// (q_m - b) / (1 + k) enters instead of q_m (the difference is added as a mass flow with the
/// enthalpy of the true flow); where the inputs declare the inlet closed (CellInputs::inlet_closed,
/// the diagnosis' zeroed meter noise) nothing flows. Valve-driven: the reading becomes
/// (1 + k) q + b. k = b = 0: off.
class InflowBiasEffect : public CellEffect {
 public:
  InflowBiasEffect(double scale_error, double offset_kg_s) : scale_error_(scale_error), offset_kg_s_(offset_kg_s) {}
  std::string name() const override { return "inflow_bias"; }
  std::map<std::string, double> parameters() const override;
  void contribute(const CellParams& params, const CellVariables& cell, const double* state, EffectTerms* terms,
                  double* state_rate) const override;
  void measure(const CellParams& params, const CellVariables& cell, const double* state,
               Readings* measurement) const override;

 private:
  bool off() const { return scale_error_ == 0.0 && offset_kg_s_ == 0.0; }
  double scale_error_;
  double offset_kg_s_;
};

/// First-order lag of the pressure reading (sensor, tubing): dp_s/dt = (p - p_s) / tau; the
/// sensor reports p_s. One state. tau = 0: off (no state, the true pressure is reported).
class PressureSensorLagEffect : public CellEffect {
 public:
  explicit PressureSensorLagEffect(double time_constant_s) : time_constant_s_(time_constant_s) {}
  std::string name() const override { return "pressure_sensor_lag"; }
  std::map<std::string, double> parameters() const override { return {{"time_constant_s", time_constant_s_}}; }
  int stateSize() const override { return time_constant_s_ > 0.0 ? 1 : 0; }
  void initialState(const CellParams& params, const CellVariables& cell, double* state) const override;
  bool readsValveFlows() const override { return false; }
  void contribute(const CellParams& params, const CellVariables& cell, const double* state, EffectTerms* terms,
                  double* state_rate) const override;
  void measure(const CellParams& params, const CellVariables& cell, const double* state,
               Readings* measurement) const override;

 private:
  double time_constant_s_;
};

/// Tube between the flow meter/inlet valve and the cell: an isothermal dead volume V_l at the
/// supply temperature (state: its gas mass, stored as its pressure m R T_supply / V_l) joined
/// to the cell by an orifice of effective area A_l. The metered inflow (prescribed, or the
/// inlet valve's flow from the regulator into the line) enters the line; the line feeds the
/// cell; the pressure is read at the line. V_l = 0: off (no state).
class SupplyLineEffect : public CellEffect {
 public:
  SupplyLineEffect(double line_volume_m3, double line_area_m2)
      : line_volume_m3_(line_volume_m3), line_area_m2_(line_area_m2) {}
  std::string name() const override { return "supply_line"; }
  std::map<std::string, double> parameters() const override;
  int stateSize() const override { return line_volume_m3_ > 0.0 ? 1 : 0; }
  void initialState(const CellParams& params, const CellVariables& cell, double* state) const override;
  void contribute(const CellParams& params, const CellVariables& cell, const double* state, EffectTerms* terms,
                  double* state_rate) const override;
  void measure(const CellParams& params, const CellVariables& cell, const double* state,
               Readings* measurement) const override;

 private:
  /// Metered flow into the line [kg/s] at line pressure p_line.
  double lineInflow(const CellParams& params, const CellVariables& cell, double line_pressure_pa) const;
  double line_volume_m3_;
  double line_area_m2_;
};

/// Coulomb friction in the plate guide, smoothed: F = -F_c tanh(v / v_s), v_s = 1 mm/s
/// (below v_s it acts as a viscous damper of F_c / v_s). F_c = 0: off.
class PlateFrictionEffect : public CellEffect {
 public:
  static constexpr double kSmoothingSpeedMS = 1.0e-3;
  explicit PlateFrictionEffect(double friction_force_n) : friction_force_n_(friction_force_n) {}
  std::string name() const override { return "plate_friction"; }
  std::map<std::string, double> parameters() const override { return {{"friction_force_n", friction_force_n_}}; }
  bool readsValveFlows() const override { return false; }
  void contribute(const CellParams& params, const CellVariables& cell, const double* state, EffectTerms* terms,
                  double* state_rate) const override;

 private:
  double friction_force_n_;
};

/// Not a candidate. The gas exchanges heat (fixed coefficient 8 W/(m^2 K) over the film's
/// wetted area) with surroundings whose temperature drifts linearly from the ambient one:
/// Q = h A (T_amb + r t - T). r = 0: off (the exchange too, so that off is the nominal model).
class AmbientDriftEffect : public CellEffect {
 public:
  static constexpr double kExchangeCoefficientWM2K = 8.0;
  explicit AmbientDriftEffect(double drift_k_s) : drift_k_s_(drift_k_s) {}
  std::string name() const override { return "ambient_drift"; }
  std::map<std::string, double> parameters() const override { return {{"drift_k_s", drift_k_s_}}; }
  bool readsValveFlows() const override { return false; }
  void contribute(const CellParams& params, const CellVariables& cell, const double* state, EffectTerms* terms,
                  double* state_rate) const override;

 private:
  double drift_k_s_;
};

/// Not a candidate. The pressure sensor's zero drifts linearly: it reports p + r t (t = run
/// time). r = 0: off.
class PressureOffsetDriftEffect : public CellEffect {
 public:
  explicit PressureOffsetDriftEffect(double drift_pa_s) : drift_pa_s_(drift_pa_s) {}
  std::string name() const override { return "pressure_offset_drift"; }
  std::map<std::string, double> parameters() const override { return {{"drift_pa_s", drift_pa_s_}}; }
  bool readsValveFlows() const override { return false; }
  void contribute(const CellParams&, const CellVariables&, const double*, EffectTerms*, double*) const override {}
  void measure(const CellParams& params, const CellVariables& cell, const double* state,
               Readings* measurement) const override;

 private:
  double drift_pa_s_;
};

/// Not a candidate (nor a channel distortion): a drag on the plate quadratic in its speed,
/// F = -c_d |v| v. c_d = 0: off.
class PlateQuadraticDragEffect : public CellEffect {
 public:
  explicit PlateQuadraticDragEffect(double drag_coefficient_n_s2_m2)
      : drag_coefficient_n_s2_m2_(drag_coefficient_n_s2_m2) {}
  std::string name() const override { return "plate_quadratic_drag"; }
  std::map<std::string, double> parameters() const override {
    return {{"drag_coefficient_n_s2_m2", drag_coefficient_n_s2_m2_}};
  }
  bool readsValveFlows() const override { return false; }
  void contribute(const CellParams& params, const CellVariables& cell, const double* state, EffectTerms* terms,
                  double* state_rate) const override;

 private:
  double drag_coefficient_n_s2_m2_;
};

/// Not a candidate: a leak whose outflow follows a power of the gauge pressure (permeation,
/// porous seams), q = q_ref (p_gauge / 10 kPa)^n for p_gauge > 0, unlike the orifice's square
/// root. q_ref = 0: off.
class PowerLeakEffect : public CellEffect {
 public:
  static constexpr double kReferencePressurePa = 1.0e4;
  PowerLeakEffect(double leak_flow_kg_s, double exponent) : leak_flow_kg_s_(leak_flow_kg_s), exponent_(exponent) {}
  std::string name() const override { return "power_leak"; }
  std::map<std::string, double> parameters() const override;
  bool readsValveFlows() const override { return false; }
  void contribute(const CellParams& params, const CellVariables& cell, const double* state, EffectTerms* terms,
                  double* state_rate) const override;

 private:
  double leak_flow_kg_s_;
  double exponent_;
};

}  // namespace nursing_bed
