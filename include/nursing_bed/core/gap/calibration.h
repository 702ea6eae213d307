// Calibration of the cell model's own uncertain parameters (doc/formats/gap_report.md, "First:
// the model's parameters, or missing physics?"): a catalogue of the parameters a rig never matches
// exactly (like the effects' catalogue: name, nominal from CellParams, prior range, how it maps
// onto CellParams), their fit on the fit runs through the same machinery as the effects
// (fit_model.h), standard errors from the Ceres covariance, and which moves are significant.
// `gap calibrate` is its command line; doc/gap_calibration.md explains the method.
#pragma once

#include <Eigen/Core>

#include <cmath>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "nursing_bed/core/gap/fit_model.h"
#include "nursing_bed/core/gap/run_data.h"
#include "nursing_bed/core/physics/cell_model.h"

namespace nursing_bed {

/// One calibratable cell parameter.
struct CalibrationParamDef {
  std::string name;         ///< canonical key (doc/formats/gap_report.md), SI unit suffix
  std::string unit;         ///< for people
  std::string description;  ///< what it is and where it enters, one line
  /// The parameter in a CellParams: read and set (film_stiffness_scale scales the three Yeoh
  /// constants of the nominal file together, so it reads 1 on any nominal file).
  double (*get)(const CellParams& p);
  void (*set)(CellParams* p, double value);
  /// Prior range relative to the nominal value: [nominal * lo_factor, nominal * hi_factor], or
  /// nominal + [lo_offset, hi_offset] when `offsets` (a length known to a few mm).
  double lo = 0.0, hi = 0.0;
  bool offsets = false;
  bool log_scale = false;
  /// Only runs driven through the model's own valves (no flow meter) tell it.
  bool valve_driven_only = false;
  /// The structure it belongs to: a structure type ("pillow": its film and gusset; "bellows"),
  /// "plate" (every structure but a bellows: the loading plate), "airway" (a cell with a series
  /// airway), or empty (any structure).
  std::string structure;
};

/// film_stiffness_scale, gusset_height_m, dead_volume_m3, plate_mass_kg, inlet_area_m2,
/// vent_area_m2, regulator_time_constant_s; for a bellows compliance_m3_pa and
/// plate_damping_n_s_m (dead_volume_m3 is the bellows' then); the series airway's
/// airway_resistance_pa_s_m3, airway_quadratic_resistance_pa_s2_m6, airway_volume_m3.
const std::vector<CalibrationParamDef>& calibrationCatalog();
/// Catalogue entry by name; throws std::invalid_argument naming the known parameters otherwise.
const CalibrationParamDef& calibrationParam(const std::string& name);
/// Groups of parameters that enter the model only together: film thickness and stiffness scale
/// appear as their product (film energy = n A0 t W), so only the scale is calibrated.
std::vector<std::vector<std::string>> structurallyUnidentifiable();

/// The fit axes of `names` around the nominal values of `nominal` (prior range as in the
/// catalogue, admissible range within physical bounds). Throws std::invalid_argument for an
/// unknown name or one given twice.
std::vector<gap::FitAxis> calibrationAxes(const std::vector<std::string>& names, const CellParams& nominal);

/// `base` with the calibrated parameters set to `values` (catalogue names; others unchanged).
CellParams applyCalibration(const std::map<std::string, double>& values, const CellParams& base);

/// Whether the run has no height reading at all (pressure sensors only).
bool runHasNoHeight(const RunData& run);

/// Whether catalogue entry `d` belongs to the structure of `nominal` (CalibrationParamDef::structure).
bool calibrationParamApplies(const CalibrationParamDef& d, const CellParams& nominal);

/// The parameters the runs can tell on the structure of `nominal`: those of its structure
/// (film_stiffness_scale, gusset_height_m, dead_volume_m3, plate_mass_kg for the pillow;
/// compliance_m3_pa, dead_volume_m3, plate_damping_n_s_m for a bellows), plus the valves' (and
/// regulator's) when a run is valve-driven, the vent's when a run vents through an unmetered
/// valve,
/// and the airway's resistances (and circuit volume, when it has one) when `nominal` has a series
/// airway, its resistance then standing for the plate's damping.
std::vector<std::string> defaultCalibrationParams(const std::vector<RunData>& runs,
                                                  const CellParams& nominal = CellParams{});
/// Checks `names` against the catalogue, the runs and the structure: throws
/// std::invalid_argument naming an unknown parameter, a valve parameter asked of runs that are
/// all flow-metered, or a parameter of another structure.
void checkCalibrationParams(const std::vector<std::string>& names, const std::vector<RunData>& runs,
                            const CellParams& nominal = CellParams{});

/// One calibrated parameter in the report.
struct CalibratedParam {
  std::string name, unit;
  double nominal = 0.0;
  double value = 0.0;      ///< the calibrated value (nominal when not moved)
  double fitted = 0.0;     ///< the fitted value, moved or not
  double std_error = NAN;  ///< from the Ceres covariance (scaled by chi2/n when above 1)
  bool moved = false;      ///< |fitted - nominal| > 2 SE and its move pays in BIC
};

/// What calibration found, for report.json's `calibration` block (doc/formats/gap_report.md).
struct CalibrationSummary {
  bool done = false;                        ///< calibration ran
  std::vector<CalibratedParam> parameters;  ///< every parameter fitted
  std::vector<std::string> correlation_names;
  Eigen::MatrixXd correlation;  ///< of the fitted values
  std::vector<std::vector<std::string>> unidentifiable;
  double chi2 = NAN;                             ///< fit runs, the calibrated model (moved parameters only)
  double bic_delta = 0.0;                        ///< against the nominal model (0 when nothing moved)
  double withheld_chi2_per_sample = NAN;         ///< calibrated model, whitened, withheld runs
  double fit_nrmse = NAN, withheld_nrmse = NAN;  ///< calibrated model alone
  std::string file = "calibrated_airbag.yaml";
  std::vector<std::string> notes;  ///< what the runs cannot tell, in words
  /// Channel distortions that fit the fit and withheld runs as well as the moved parameters do
  /// (a pressure gain against the film stiffness on one load), each with its fitted values.
  std::vector<std::pair<std::string, std::map<std::string, double>>> distortion_ties;
  std::map<std::string, double> movedValues() const;
  bool anyMoved() const { return !movedValues().empty(); }
};

/// A complete parameter file: `params` as YAML (every key, commented), headed by what was
/// calibrated and from which dataset.
std::string calibratedParamsYaml(const CellParams& params, const CalibrationSummary& summary,
                                 const std::string& dataset);

}  // namespace nursing_bed
