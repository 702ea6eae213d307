// The fitting machinery of the gap diagnosis (doc/gap_diagnosis.md, "Fitting"): a candidate
// model (nominal cell plus effects) in fit coordinates, the fit runs with their noise floor, the
// whitened replay residuals, and the Levenberg-Marquardt fit of a model from a grid of starts.
#pragma once

#include <Eigen/Core>

#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "nursing_bed/core/gap/effects.h"
#include "nursing_bed/core/gap/replay.h"
#include "nursing_bed/core/gap/run_data.h"
#include "nursing_bed/core/physics/cell_model.h"

namespace nursing_bed {
namespace gap {

// ---- fit coordinates ------------------------------------------------------------------------
// Each fitted parameter is mapped to u, with u = 0 .. 1 spanning its plausible range (on a log
// scale where the catalogue says so), so that one step size and one trust region suit all.

struct FitAxis {
  /// The parameter: an effect's (effects.h), or a cell parameter that calibration fits
  /// (calibration.h; its off_value is the nominal value, lo .. hi its prior range).
  EffectParamSpec spec;
  bool calibration = false;         ///< a cell parameter (CellParams), not an effect's
  double u_min = 0.0, u_max = 1.0;  ///< bounds: the admissible range, at most 3 decades/widths past

  double toValue(double u) const;
  double toU(double x) const;
};

FitAxis makeAxis(const EffectParamSpec& p, bool calibration = false);

/// A candidate model: the cell with its calibrated parameters `calibration` (calibration.h;
/// the others at their values in FitData::params) plus `effects`, and the axes of all their
/// parameters.
struct ModelSpec {
  std::vector<std::string> effects;
  std::vector<std::string> calibration;  ///< calibrated cell parameters (their axes come first)
  std::vector<FitAxis> axes;             ///< calibrated parameters, then every parameter of every effect
  /// Calibrated cell parameters held at these values (not fitted; a free one overrides).
  std::map<std::string, double> fixed_calibration;
};

/// `effects` on top of a cell whose parameters `calibration` (calibrationAxes()) are fitted too.
ModelSpec makeModelSpec(const std::vector<std::string>& effects, const std::vector<FitAxis>& calibration = {});
std::map<std::string, double> valuesOf(const ModelSpec& m, const std::vector<double>& u);
std::vector<CellEffectPtr> buildEffects(const ModelSpec& m, const std::map<std::string, double>& values);
/// `base` (the nominal cell) with the model's fixed calibration and its calibrated parameters set
/// to `values` (applyCalibration()).
CellParams modelParams(const ModelSpec& m, const std::map<std::string, double>& values, const CellParams& base);
/// The fit coordinates of `values` (every axis' parameter must be there).
std::vector<double> coordinatesOf(const ModelSpec& m, const std::map<std::string, double>& values);
/// Every effect parameter within its plausible range widened by `slack` (too large only, for
/// log-scale); calibrated parameters are judged by calibration (calibration.h).
bool plausibleValues(const ModelSpec& m, const std::map<std::string, double>& values, double slack);
/// Every channel time shift or lag of `values` at least 1 ms (below, it is the replay's own
/// timing: plausibleValues() refuses it whatever the rest).
bool timingResolved(const ModelSpec& m, const std::map<std::string, double>& values);
/// "leak+heat_transfer"; "nominal" for none.
std::string joinNames(const std::vector<std::string>& names, const char* sep = "+");

// ---- the fit runs and their noise floor -------------------------------------------------------

/// The fit runs with the samples that enter the fit and their noise floor (noise_model.h).
struct FitData {
  struct Run {
    const RunData* data = nullptr;
    std::vector<std::size_t> index;  ///< samples used
    std::vector<double> sigma_p_pa;  ///< noise floor at those samples (its diagonal)
    std::vector<double> sigma_h_m;
    /// The diagonal's parts, squared (ASME V&V 20's validation uncertainty, validation.h): the
    /// data's (sensor noise), the replay's numerical (its accuracy, the timing spread) and the
    /// inputs' (the flow meter's noise integrated, the start height, the timing's offsets).
    std::vector<double> var_data_p, var_num_p, var_input_p, var_data_h, var_num_h, var_input_h;
    /// Cholesky factor of the correlation of the floor-scaled residuals [p0, h0, p1, h1, ...]:
    /// the integrated flow-meter noise is one random walk of the gas mass, shared by all
    /// samples after it, so those residuals are correlated; the fit whitens them with it.
    Eigen::MatrixXd correlation_cholesky;
    long max_substeps = 0;   ///< integration budget of one replay (see replayRun)
    bool has_height = true;  ///< false: no height sensor; its residual slots stay 0
  };
  std::vector<Run> runs;
  CellParams params;  ///< with the fit's integration settings
  /// Runs replayed in parallel by fitResiduals() (a fit alone on the machine, as the calibration's
  /// and the first joint refit are, then uses every core).
  int threads = 1;
  /// Residual slots (two per sample: the layout of fitResiduals()).
  int residualCount() const;
  /// Residuals that carry a reading (the n of chi2/n and BIC): slots less the height slots of
  /// runs without a height sensor.
  int informativeCount() const;
};

/// Whitened residuals of every fit sample (pressure then height per sample, scaled by the
/// floor, then decorrelated per run) into `out` (residualCount() values); false when a replay
/// failed (its samples then count as kFailedResidual floors off).
bool fitResiduals(const FitData& fit, const std::vector<CellEffectPtr>& effects, double* out);
/// The same on a cell of `params` (a calibrated one) instead of fit.params.
bool fitResiduals(const FitData& fit, const CellParams& params, const std::vector<CellEffectPtr>& effects, double* out);
double sumSquares(const std::vector<double>& r);

// ---- fitting ----------------------------------------------------------------------------------

/// Starting points: a grid over the plausible range (5 points per parameter, 4 with two or
/// more parameters; plus one near off for log-scale ones).
std::vector<std::vector<double>> gridStarts(const ModelSpec& m);
/// gridStarts() and, for a height offset alone, the offset that reads the fit runs' mean first
/// height as a flat start, where that lies beyond the grid and within the fit's bounds: past a
/// few mm the replay's start moves with the offset (undoHeightReadingDistortions()), and from
/// the grid's points a fit cannot reach the offset that starts the runs flat.
std::vector<std::vector<double>> fitStarts(const FitData& fit, const ModelSpec& m);

struct FitOutcome {
  std::vector<double> u;  ///< best fit coordinates
  double chi2 = NAN;      ///< whitened, summed, at u
  bool ok = false;
  int evaluations = 0;  ///< replays of the fit-run set
  int iterations = 0;   ///< Levenberg-Marquardt iterations of its solves (steps taken or rejected)
  std::string message;
  /// Stopped early: at its pace it could not get below the fit's `overtake_chi2` (fitModel()).
  bool stopped = false;
};

/// Axes of `model` that the fit runs cannot tell from the cell's own parameters, held at their
/// off value: a flow meter's scale error (inflow_bias) on runs without a height reading of a cell
/// with a compliance, whose pressure follows V/C with V the metered volume, so that reading
/// (1 + k) times the flow is a compliance C (1 + k) (doc/gap_real_recordings.md).
std::vector<int> heldAxes(const FitData& fit, const ModelSpec& model);

/// Levenberg-Marquardt (Ceres) from the best one (two, with two or more parameters) of
/// `starts` (repeated starts solved once), the heldAxes() at their off value; the best result.
/// A fit that matters only if it overtakes another's chi2 gets that as `overtake_chi2`: it stops
/// (FitOutcome::stopped) once, at its best pace of the last iterations, it could not get below it
/// within `max_iterations`.
FitOutcome fitModel(const FitData& fit, const ModelSpec& model, const std::vector<std::vector<double>>& starts,
                    int max_iterations, double overtake_chi2 = INFINITY);

/// Covariance of the fit coordinates at `u`: (J^T J)^-1 of the whitened residuals, J from the
/// Ceres cost (forward differences of whole replays). Directions the runs cannot tell (eigenvalues
/// of J^T J below 1e-9 of the largest) get no inverse; the parameters in them an infinite
/// variance. False when a replay fails.
bool fitCovariance(const FitData& fit, const ModelSpec& model, const std::vector<double>& u, Eigen::MatrixXd* cov);

}  // namespace gap
}  // namespace nursing_bed
