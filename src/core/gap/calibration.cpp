// Calibration of the cell model's own parameters (calibration.h, doc/gap_calibration.md): the
// catalogue, the stage that fits it on the fit runs, and the judgement of each move.
#include "nursing_bed/core/gap/calibration.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/gap/diagnosis_stages.h"
#include "nursing_bed/core/physics/cell_params_io.h"

namespace nursing_bed {
namespace {

double filmScale(const CellParams&) { return 1.0; }
void setFilmScale(CellParams* p, double s) {
  p->structure.material.c10_pa *= s;
  p->structure.material.c20_pa *= s;
  p->structure.material.c30_pa *= s;
}

bool isBellows(const CellParams& p) { return p.structure_type == "bellows"; }
double deadVolume(const CellParams& p) { return isBellows(p) ? p.bellows.dead_volume_m3 : p.structure.dead_volume_m3; }
void setDeadVolume(CellParams* p, double v) {
  (isBellows(*p) ? p->bellows.dead_volume_m3 : p->structure.dead_volume_m3) = v;
}

#define NB_CAL_ACCESS(expr) \
  [](const CellParams& p) -> double { return p.expr; }, [](CellParams* p, double v) { p->expr = v; }

std::vector<CalibrationParamDef> makeCatalog() {
  return {
      {"film_stiffness_scale", "-",
       "the film's Yeoh constants C10, C20, C30 scaled together (film batch; equals a thickness "
       "scale: thickness and stiffness enter as their product)",
       filmScale, setFilmScale, 0.7, 1.4, false, false, false, "pillow"},
      {"gusset_height_m", "m", "unstretched side-gusset height of one chamber (seams, cutting)",
       NB_CAL_ACCESS(structure.gusset_height_m), -0.008, 0.008, true, false, false, "pillow"},
      {"dead_volume_m3", "m^3",
       "gas volume of the flat cell (inlet fitting, tube stub, folds) or of a bellows at zero travel", deadVolume,
       setDeadVolume, 0.3, 3.5, false, true, false, ""},
      {"plate_mass_kg", "kg", "mass of the loading plate alone (inertia of a lightly loaded plate)",
       NB_CAL_ACCESS(plate_mass_kg), 0.7, 1.4, false, false, false, "plate"},
      // A test lung's setting is nominal to about 10 %; the prior spans a factor 2 either way.
      {"compliance_m3_pa", "m^3/Pa", "bellows compliance C = A^2 / k: volume per gauge pressure of its spring",
       NB_CAL_ACCESS(bellows.compliance_m3_pa), 0.5, 2.0, false, true, false, "bellows"},
      {"plate_damping_n_s_m", "N s/m", "viscous damping of the bellows' plate (fold and hinge friction)",
       NB_CAL_ACCESS(plate_damping_n_s_m), 0.1, 10.0, false, true, false, "bellows"},
      // A ventilator circuit's resistor spans 5-50 cmH2O/(L/s) around a nominal near 20.
      {"airway_resistance_pa_s_m3", "Pa s/m^3", "series airway: linear term R1 of its resistor",
       NB_CAL_ACCESS(airway.resistance_pa_s_m3), 0.2, 3.0, false, true, false, "airway"},
      {"airway_quadratic_resistance_pa_s2_m6", "Pa s^2/m^6", "series airway: quadratic term R2 of its resistor",
       NB_CAL_ACCESS(airway.quadratic_resistance_pa_s2_m6), 0.1, 5.0, false, true, false, "airway"},
      {"airway_volume_m3", "m^3", "series airway: circuit gas volume upstream of its resistor",
       NB_CAL_ACCESS(airway.volume_m3), 0.3, 3.0, false, true, false, "airway"},
      {"inlet_area_m2", "m^2", "effective area Cd*A of the open inlet valve", NB_CAL_ACCESS(inlet_area_m2), 0.5, 2.0,
       false, true, true, ""},
      {"vent_area_m2", "m^2", "effective area Cd*A of the open vent valve", NB_CAL_ACCESS(vent_area_m2), 0.5, 2.0,
       false, true, true, ""},
      {"regulator_time_constant_s", "s", "first-order response time of the supply regulator's outlet",
       NB_CAL_ACCESS(regulator_time_constant_s), 0.5, 2.0, false, true, true, ""},
  };
}
#undef NB_CAL_ACCESS

/// Admissible range of a parameter around `nominal`: physical bounds, wide enough for any rig.
void admissibleRange(const CalibrationParamDef& d, double nominal, double* lo, double* hi) {
  if (d.offsets) {
    *lo = std::max(0.2 * nominal, nominal - 0.03);
    *hi = nominal + 0.03;
  } else if (d.log_scale) {
    *lo = nominal * 0.02;
    *hi = nominal * 50.0;
  } else {
    *lo = nominal * 0.2;
    *hi = nominal * 5.0;
  }
}

bool allNaN(const std::vector<double>& v) {
  return std::none_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

}  // namespace

const std::vector<CalibrationParamDef>& calibrationCatalog() {
  static const std::vector<CalibrationParamDef> catalog = makeCatalog();
  return catalog;
}

const CalibrationParamDef& calibrationParam(const std::string& name) {
  return catalogEntry(calibrationCatalog(), name, "calibration parameter");
}

std::vector<std::vector<std::string>> structurallyUnidentifiable() {
  return {{"film_stiffness_scale", "film_thickness_m"}};
}

std::vector<gap::FitAxis> calibrationAxes(const std::vector<std::string>& names, const CellParams& nominal) {
  std::vector<gap::FitAxis> axes;
  std::set<std::string> seen;
  for (const auto& name : names) {
    const CalibrationParamDef& d = calibrationParam(name);
    if (!seen.insert(name).second) throw std::invalid_argument("calibration parameter '" + name + "' given twice");
    const double x0 = d.get(nominal);
    if (!(x0 > 0.0) || !std::isfinite(x0))
      throw std::invalid_argument("calibration parameter '" + name + "': its nominal value " + gap::fmt(x0) +
                                  " is not positive; it cannot be calibrated around it");
    EffectParamSpec s;
    s.name = d.name;
    s.unit = d.unit;
    s.description = d.description;
    s.off_value = x0;
    s.lo = d.offsets ? x0 + d.lo : x0 * d.lo;
    s.hi = d.offsets ? x0 + d.hi : x0 * d.hi;
    s.log_scale = d.log_scale;
    admissibleRange(d, x0, &s.min_value, &s.max_value);
    axes.push_back(gap::makeAxis(s, true));
  }
  return axes;
}

CellParams applyCalibration(const std::map<std::string, double>& values, const CellParams& base) {
  CellParams p = base;
  for (const auto& [name, v] : values) calibrationParam(name).set(&p, v);
  return p;
}

bool runHasNoHeight(const RunData& run) { return allNaN(run.h_m); }

bool calibrationParamApplies(const CalibrationParamDef& d, const CellParams& nominal) {
  if (d.structure.empty()) return true;
  if (d.structure == "airway") return nominal.airway.active();
  if (d.structure == "plate") return !isBellows(nominal);
  return d.structure == nominal.structure_type;
}

std::vector<std::string> defaultCalibrationParams(const std::vector<RunData>& runs, const CellParams& nominal) {
  bool valve_driven = false, unmetered_vent = false;
  for (const auto& r : runs) {
    valve_driven = valve_driven || runIsValveDriven(r);
    unmetered_vent = unmetered_vent || (!runIsValveDriven(r) && ventsThroughUnmeteredValve(r));
  }
  std::vector<std::string> names;
  // The plate's damping acts on the chamber's pressure as a linear resistance in series: with an
  // airway resistor the two are one parameter, and the airway's is the one calibrated.
  const bool damping_told = nominal.airway.resistance_pa_s_m3 <= 0.0;
  // A bellows' volume is linear in its pressure, V = V0 + C p: its dead volume enters the
  // pressure only through the gas' compressibility, V0 / (gamma p), one more compliance. Without
  // a height reading the two are one parameter, and the compliance is the one calibrated.
  const bool pressure_only = std::all_of(runs.begin(), runs.end(), runHasNoHeight);
  const bool dead_volume_told = !isBellows(nominal) || !pressure_only;
  for (const auto& d : calibrationCatalog())
    if (calibrationParamApplies(d, nominal) && (damping_told || d.name != "plate_damping_n_s_m") &&
        (dead_volume_told || d.name != "dead_volume_m3") &&
        (d.name != "airway_volume_m3" || nominal.airway.volume_m3 > 0.0) &&
        (!d.valve_driven_only || valve_driven || (unmetered_vent && d.name == "vent_area_m2")))
      names.push_back(d.name);
  return names;
}

void checkCalibrationParams(const std::vector<std::string>& names, const std::vector<RunData>& runs,
                            const CellParams& nominal) {
  const std::vector<std::string> told = defaultCalibrationParams(runs, nominal);
  for (const auto& n : names) {
    const CalibrationParamDef& d = calibrationParam(n);
    if (!calibrationParamApplies(d, nominal))
      throw std::invalid_argument("calibration parameter '" + n + "' belongs to the " +
                                  (d.structure == "airway"
                                       ? std::string("series airway, which the cell has not")
                                       : d.structure + "; the cell's structure is " + nominal.structure_type));
    if (d.valve_driven_only && std::find(told.begin(), told.end(), n) == told.end())
      throw std::invalid_argument("calibration parameter '" + n +
                                  "' needs runs driven through the model's valves (no mdot_in_kg_s column, but "
                                  "valve_cmd and p_supply_gauge_pa); every run here is flow-metered");
  }
}

std::map<std::string, double> CalibrationSummary::movedValues() const {
  std::map<std::string, double> out;
  for (const auto& p : parameters)
    if (p.moved) out[p.name] = p.value;
  return out;
}

std::string calibratedParamsYaml(const CellParams& params, const CalibrationSummary& summary,
                                 const std::string& dataset) {
  std::ostringstream y;
  y << "# Cell parameters calibrated by `gap calibrate` on the fit runs of " << dataset << ".\n"
    << "# A complete parameter file (every key, SI units): sim.launch cell_params:=FILE, the nodes and\n"
    << "# gap diagnose read it as they read config/airbag_tpu_double_100.yaml.\n";
  for (const auto& p : summary.parameters)
    y << "# " << p.name << ": " << (p.moved ? "calibrated " : "kept at nominal ") << gap::fmt(p.value, 6) << " ["
      << p.unit << "] (nominal " << gap::fmt(p.nominal, 6) << ", fitted " << gap::fmt(p.fitted, 6) << " +- "
      << gap::fmt(p.std_error, 2) << ")\n";
  y << "# film_stiffness_scale multiplies material/c10_pa, c20_pa, c30_pa below (film thickness is kept: the\n"
    << "# model sees only their product).\n";
  return y.str() + cellParamsToYaml(params);
}

}  // namespace nursing_bed
