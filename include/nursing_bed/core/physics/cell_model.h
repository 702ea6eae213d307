// Control-volume model of one airbag cell under a loaded rigid plate (paper section 4.1).
#pragma once

#include <Eigen/Dense>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "nursing_bed/core/physics/airway.h"
#include "nursing_bed/core/physics/bellows_structure.h"
#include "nursing_bed/core/physics/cell_effect.h"
#include "nursing_bed/core/physics/cell_structure.h"
#include "nursing_bed/core/physics/gas.h"
#include "nursing_bed/core/physics/pillow_structure.h"
#include "nursing_bed/core/physics/step_matrix.h"
#include "nursing_bed/core/physics/time_series.h"
#include "nursing_bed/core/physics/units.h"

namespace nursing_bed {

/// Parameters of one cell with its valves. SI units; defaults and their sources are in
/// config/airbag_tpu_double_100.yaml and doc/cell_model.md.
// size: one knob per physical constant of the cell and its valves, and the integrator's
struct CellParams {
  GasProperties gas;
  double ambient_pressure_pa = kAtmosphericPressurePa;
  double ambient_temperature_k = kRoomTemperatureK;
  double supply_temperature_k = kRoomTemperatureK;  ///< temperature of the supplied air

  PillowParams structure;  ///< geometry and film
  /// Structure model: "pillow" (PillowStructure from `structure`), "table" (a
  /// TabulatedStructure read from structure_table_file, e.g. written by fe_airbag; the film
  /// shape then relaxes in structure.film_relaxation_time_s), "fold_table" (two FE tables, folded
  /// and open at the middle connection, with hysteresis) or "bellows" (from `bellows`).
  std::string structure_type = "pillow";
  BellowsParams bellows;             ///< used when structure_type is "bellows"
  std::string structure_table_file;  ///< table path (YAML keys structure/type, structure/table_file)
  /// Series airway between the meter/sensor and the chamber (none by default); CellModel adds
  /// it as the first effect when active.
  AirwayParams airway;

  double plate_mass_kg = 0.6 / kGravity;  ///< loading plate (0.6 N, paper section 2.2)
  double plate_damping_n_s_m = 20.0;      ///< viscous damping of the plate guide
  /// Folded film stack and bed under a bottomed plate (h < 0). With the folds' depth delta
  /// (FlatFold) it sets the largest load the gas lifts off the flat cell smoothly, k delta.
  double bed_contact_stiffness_n_m = 2.0e6;
  /// Hunt-Crossley damping alpha of that contact: force k x (1 + alpha dx/dt) at depth x = -h
  /// [s/m]; a landing faster than about 1/alpha is nearly plastic.
  double bed_contact_damping_s_m = 30.0;

  double supply_pressure_pa = 20.0e3;      ///< pressure-reducing valve setting (gauge)
  double regulator_time_constant_s = 1.2;  ///< first-order response of that valve's outlet
  double inlet_area_m2 = 1.5e-5;           ///< effective area Cd*A of the open inlet valve
  double vent_area_m2 = 1.5e-5;            ///< effective area Cd*A of the open vent valve
  double leak_area_m2 = 0.0;               ///< effective area of seams/film leakage (eq. 17)
  double orifice_linear_band_pa = 100.0;   ///< smoothing band of orifice flow near dp = 0
  /// Spring-loaded relief valve to ambient, beside the vent: closed below the cracking pressure,
  /// opening in proportion to the gauge pressure up to fully open, flow after ISO 6358. It caps
  /// the pressure a sudden outside load drives the gas to (the controller's relief acts through
  /// the vent, which an outside load can outrun).
  double relief_cracking_pressure_pa = 34000.0;      ///< gauge pressure where it starts to open
  double relief_full_open_pressure_pa = 37000.0;     ///< gauge pressure where it is fully open
  double relief_sonic_conductance_m3_s_pa = 3.0e-7;  ///< ISO 6358 C of the open valve; 0 = none
  double relief_critical_ratio = 0.3;                ///< ISO 6358 b [-]
  /// Opening 0..1 of the relief valve at `gauge_pressure_pa`.
  double reliefOpening(double gauge_pressure_pa) const;

  double time_step_s = 2.0e-3;  ///< default integration step, the largest of step()
  /// Longest step advance() takes where the local error estimate allows it (a holding cell);
  /// never shorter than time_step_s.
  double max_time_step_s = 0.02;
  int jacobian_refresh_steps = 8;      ///< accepted steps between Jacobian updates (steps > 5 ms: see CellModel)
  double relative_tolerance = 1.0e-4;  ///< local error control of the sub-steps

  /// Empty when valid, else every problem found, separated by "; ".
  std::string validate() const;
};

/// Commands and boundary conditions, held over a step.
struct CellInputs {
  double inlet_opening = 0.0;  ///< inlet valve opening 0 (closed) .. 1 (open); proportional
  double vent_opening = 0.0;   ///< vent valve opening 0 .. 1
  /// Gauge pressure at the vent's outlet: 0 vents to ambient; < 0 is a vacuum source (the
  /// vacuum-assisted rapid deflation of CPR mattresses).
  double vent_back_pressure_pa = 0.0;
  double load_n = 0.6;  ///< external vertical load on the plate, plate weight included
  /// Pressure-reducing valve setting (gauge); NaN uses CellParams::supply_pressure_pa.
  double supply_pressure_pa = std::numeric_limits<double>::quiet_NaN();
  /// When set, the inlet mass flow is this series [kg/s vs s] (a measured curve, the paper's
  /// way); the regulator and inlet valve are bypassed. Not owned.
  const TimeSeries* prescribed_inflow = nullptr;
  /// When finite (and no series is set), the inlet mass flow is this constant over the step
  /// [kg/s]: a meter that reports the mean flow of each sample interval.
  double prescribed_inflow_kg_s = std::numeric_limits<double>::quiet_NaN();
  /// With a prescribed inflow: the inlet is known to be closed over this step (a replay set the
  /// meter's noise there to 0), so effects that model the meter's errors add nothing.
  bool inlet_closed = false;
  /// When finite, the gauge pressure in the cell that its inlet, vent, leak and relief flows
  /// see over the step, instead of the model's own: an observer gives the measured pressure,
  /// so that a model pressure still wrong by an unknown load does not change the gas let in.
  double flow_gauge_pressure_pa = std::numeric_limits<double>::quiet_NaN();
};

/// The structure `params` select: the pillow model of params.structure, a bellows, or the table
/// of params.structure_table_file ("table", "fold_table"; read once per process and shared while
/// the file and the numbers are the same). Throws std::invalid_argument / std::runtime_error for
/// a table that cannot be read.
std::shared_ptr<const CellStructure> makeCellStructure(const CellParams& params);

/**
 * State x = [m, U, h, v, p_reg, q_1..q_k, effect states]:
 *  - gas mass m and internal energy U (ideal gas, constant heat capacities, adiabatic unless
 *    an effect adds heat; eq. 12-16), mass balance eq. 17;
 *  - plate height h and velocity v (rigid plate carrying the load, fig. 7);
 *  - regulator outlet gauge pressure p_reg;
 *  - film shape q (CellStructure), relaxing viscously to its balance dW/dq = p_gauge dV/dq;
 *  - states of plugged-in effects.
 * Integrated with ROS2, a second-order L-stable linearly implicit (Rosenbrock-W) method whose
 * Jacobian is refreshed every `jacobian_refresh_steps` accepted steps, and on a step longer than
 * 5 ms unless it passed a secant test over the last step (there only a Jacobian that describes
 * the current state damps the stiff modes): the plate on its gas spring and the film are stiff,
 * the gas balances are not. A step of the default size is
 * split into sub-steps when the local error estimate (ROS2 against its embedded first-order
 * solution) exceeds the tolerance, as it does while the bag lifts off a bottomed plate.
 */
// size: the model and its ROS2 integrator's step control, kept together on the hot path
class CellModel {
 public:
  static constexpr int kMaxStates = kMaxCellStates;
  using StateVector = CellStateVector;
  using StateMatrix = CellStateMatrix;
  enum StateIndex { kMass = 0, kEnergy = 1, kHeight = 2, kVelocity = 3, kRegulator = 4, kShape = 5 };

  /// Throws std::invalid_argument when params.validate() fails. The default structure is a
  /// PillowStructure built from params.structure.
  explicit CellModel(const CellParams& params, std::shared_ptr<const CellStructure> structure = nullptr);

  /// Adds an effect and resets the model (its states join the state vector).
  void addEffect(CellEffectPtr effect);
  const std::vector<CellEffectPtr>& effects() const { return effects_; }

  /// Flat cell with ambient air, plate on the bed, t = 0.
  void reset(double load_n = 0.6);
  /// Plate at rest at `height_m` under `load_n` with the gas that holds it there.
  /// The gas is at `gas_temperature_k` (NaN: the ambient temperature).
  void resetToEquilibrium(double height_m, double load_n,
                          double gas_temperature_k = std::numeric_limits<double>::quiet_NaN());

  /// One step of `dt` (default params().time_step_s), in sub-steps no longer than `dt`.
  void step(const CellInputs& inputs) { step(params_.time_step_s, inputs); }
  void step(double dt, const CellInputs& inputs) { integrate(dt, dt, inputs); }
  /// Integrates until `duration_s` has passed, in steps the error estimate sizes, from the
  /// default step up to params().max_time_step_s.
  void advance(double duration_s, const CellInputs& inputs);

  double time() const { return time_; }
  /// Accepted integration sub-steps since construction (the cost of what was simulated).
  long substeps() const { return substeps_; }
  /// Makes step() throw std::runtime_error once substeps() would exceed `max_substeps`
  /// (0: no limit). For fits that may wander into needlessly stiff parameters.
  void setSubstepBudget(long max_substeps) { substep_budget_ = max_substeps; }
  const CellVariables& variables() const { return vars_; }
  /// What the sensors report (true values unless an effect changes them).
  Readings measure() const;
  /// The flow meter's reading integrated over time since the last reset (trapezoids on the
  /// integration's sub-steps): the gas a totalising meter counted, however the flow changed
  /// between two reads [kg].
  double meteredInletMassKg() const { return metered_inlet_mass_kg_; }
  const StateVector& state() const { return state_; }
  /// Replaces the state (size must match); variables are recomputed. `keep_jacobian`: the new
  /// state is near the old one (an observer's correction), so the Jacobian and step size are
  /// kept until their usual refresh (the W-method stays second order with a stale Jacobian).
  void setState(double time_s, const StateVector& state, bool keep_jacobian = false);
  const CellParams& params() const { return params_; }
  const CellStructure& structure() const { return *structure_; }
  int stateSize() const { return static_cast<int>(state_.size()); }

  /// True when two input sets would give the same right-hand side.
  static bool sameInputs(const CellInputs& a, const CellInputs& b);
  /// Right-hand side dx/dt at (t, x); fills `vars` when non-null.
  StateVector rate(double time_s, const StateVector& x, const CellInputs& inputs, CellVariables* vars = nullptr) const {
    return rateAndEffectPart(time_s, x, inputs, vars, nullptr);
  }
  /// d rate / dx at (t, x), assembled from the model's equations (the valve flows' slopes in
  /// closed form, the relief's and the structure's by differences of those parts alone); what
  /// effects add, by finite differences of their part of the rate.
  StateMatrix jacobian(double time_s, const StateVector& x, const CellInputs& inputs) const;
  /// d(rate)/dt at fixed state: a prescribed inflow series' slope (the one ahead at its samples)
  /// and a forward difference of what effects add. The Rosenbrock stages' time term.
  StateVector timeDerivative(double time_s, const StateVector& x, const CellInputs& inputs) const;

 private:
  void refreshVariables(const CellInputs& inputs);
  void updateJacobian(const CellInputs& inputs);
  /// The structure evaluated at the height (0) and each shape (1...) moved by the Jacobian's
  /// difference step.
  using PerturbedStructures = std::array<StructureEval, 1 + kMaxShapeDofs>;
  /// The nominal cell's Jacobian at the variables `v` of its state (no effects); fills
  /// `perturbed` when given.
  StateMatrix nominalJacobian(const CellInputs& inputs, const CellVariables& v,
                              PerturbedStructures* perturbed = nullptr) const;
  /// jacobian() at the variables `v` of (t, x).
  StateMatrix jacobianAt(double time_s, const StateVector& x, const CellInputs& inputs, const CellVariables& v) const;
  /// The rate with the effects' terms minus the rate without them, at (t, x); `structure`, when
  /// given, is the structure's evaluation at x's height and shape.
  StateVector effectPart(double time_s, const StateVector& x, const CellInputs& inputs,
                         const StructureEval* structure = nullptr) const;
  /// rate(); `effect_part`, when given, receives what the effects add to it (effectPart).
  StateVector rateAndEffectPart(double time_s, const StateVector& x, const CellInputs& inputs, CellVariables* vars,
                                StateVector* effect_part) const;
  /// timeDerivative() at the variables `v` of (t, x); `effect_part`, when given, is effectPart there.
  StateVector timeDerivativeAt(double time_s, const StateVector& x, const CellInputs& inputs, const CellVariables& v,
                               const StateVector* effect_part) const;
  /// Sub-steps of at most `max_step_s` until `duration_s` has passed.
  void integrate(double duration_s, double max_step_s, const CellInputs& inputs);
  /// Accepts `next` as the state after a sub-step of `h` whose error norm was `err`; returns
  /// the size proposed for the next sub-step.
  double acceptSubstep(double h, double err, const StateVector& next, const CellInputs& inputs);
  /// Whether jacobian_ predicts the change of rate over the step just taken (dx from the state
  /// whose rate was `rate_before`): the secant test that lets a long step keep it.
  bool jacobianTracksStep(double h, const StateVector& dx, const StateVector& rate_before) const;
  /// The error norm's weight of state i: its typical magnitude plus its present size.
  double errorScale(int i) const { return scale_[i] + std::fabs(state_[i]); }
  /// One ROS2 attempt of size dt from the current state; returns the scaled error norm.
  double attemptStep(double dt, const CellInputs& inputs, const StateVector& f0, StateVector* next);
  /// attemptStep for the nominal size (fixed-size vectors).
  double attemptNominalStep(double dt, const CellInputs& inputs, const StateVector& f0, StateVector* next);

  CellParams params_;
  std::shared_ptr<const CellStructure> structure_;
  std::vector<CellEffectPtr> effects_;
  bool effects_read_flows_ = false;  // some effect reads the valves' flows (readsValveFlows)
  std::vector<int> effect_offsets_;
  int shape_dofs_ = 1;
  double time_ = 0.0;
  StateVector state_;
  CellVariables vars_;
  CellInputs last_inputs_;
  // W-method bookkeeping.
  StateMatrix jacobian_;
  bool jacobian_fresh_ = false;  // computed at the current state
  int steps_since_jacobian_ = 1 << 30;
  bool jacobian_tracks_ = false;  // jacobian_ predicted the last step's change of rate
  double lu_dt_ = 0.0;            // step size the factorisation was made for
  StepMatrix step_matrix_;
  StateVector scale_;       // typical magnitude of each state (FD increments, tolerances)
  double substep_s_ = 0.0;  // last accepted sub-step size
  long substeps_ = 0;
  double metered_inlet_mass_kg_ = 0.0;  ///< meteredInletMassKg()
  double metered_flow_at_state_ = 0.0;  ///< the meter's reading at (time_, state_), kept with vars_
  long substep_budget_ = 0;
  StateVector rate_at_state_;         // dx/dt at (time_, state_, last_inputs_), kept with vars_
  StateVector effect_part_at_state_;  // what the effects add to it (with effects only)
};

}  // namespace nursing_bed
