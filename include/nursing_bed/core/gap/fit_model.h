// The fitting machinery of the gap diagnosis (doc/gap_diagnosis.md, "Fitting"): a candidate
// model (nominal cell plus effects) in fit coordinates, the fit runs with their noise floor, the
// whitened replay residuals, and the Levenberg-Marquardt fit of a model from a grid of starts.
#pragma once

#include <Eigen/Core>

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
  const EffectParamSpec* spec = nullptr;
  double u_min = 0.0, u_max = 1.0;  ///< bounds: the admissible range, at most 3 decades/widths past

  double toValue(double u) const;
  double toU(double x) const;
};

FitAxis makeAxis(const EffectParamSpec& p);

/// A candidate model: the nominal cell plus `effects`, and the axes of all their parameters.
struct ModelSpec {
  std::vector<std::string> effects;
  std::vector<FitAxis> axes;  ///< every parameter of every effect, in order
};

ModelSpec makeModelSpec(const std::vector<std::string>& names);
std::map<std::string, double> valuesOf(const ModelSpec& m, const std::vector<double>& u);
std::vector<CellEffectPtr> buildEffects(const ModelSpec& m, const std::map<std::string, double>& values);
/// Every parameter within its plausible range widened by `slack` (too large only, for log-scale).
bool plausibleValues(const ModelSpec& m, const std::map<std::string, double>& values, double slack);
/// "leak+heat_transfer"; "nominal" for none.
std::string joinNames(const std::vector<std::string>& names, const char* sep = "+");

// ---- the fit runs and their noise floor -------------------------------------------------------

/// The fit runs with the samples that enter the fit and their noise floor (noise_model.h).
struct FitData {
  struct Run {
    const RunData* data = nullptr;
    std::vector<std::size_t> index;   ///< samples used
    std::vector<double> sigma_p_pa;   ///< noise floor at those samples (its diagonal)
    std::vector<double> sigma_h_m;
    /// Cholesky factor of the correlation of the floor-scaled residuals [p0, h0, p1, h1, ...]:
    /// the integrated flow-meter noise is one random walk of the gas mass, shared by all
    /// samples after it, so those residuals are correlated; the fit whitens them with it.
    Eigen::MatrixXd correlation_cholesky;
    long max_substeps = 0;            ///< integration budget of one replay (see replayRun)
  };
  std::vector<Run> runs;
  CellParams params;  ///< with the fit's integration settings
  int residualCount() const;
};

/// Whitened residuals of every fit sample (pressure then height per sample, scaled by the
/// floor, then decorrelated per run) into `out` (residualCount() values); false when a replay
/// failed (its samples then count as kFailedResidual floors off).
bool fitResiduals(const FitData& fit, const std::vector<CellEffectPtr>& effects, double* out);
double sumSquares(const std::vector<double>& r);

// ---- fitting ----------------------------------------------------------------------------------

/// Starting points: a grid over the plausible range (5 points per parameter, 4 with two or
/// more parameters; plus one near off for log-scale ones).
std::vector<std::vector<double>> gridStarts(const ModelSpec& m);

struct FitOutcome {
  std::vector<double> u;  ///< best fit coordinates
  double chi2 = NAN;      ///< whitened, summed, at u
  bool ok = false;
  int evaluations = 0;    ///< replays of the fit-run set
  std::string message;
};

/// Levenberg-Marquardt (Ceres) from the best one (two, with two or more parameters) of
/// `starts`; the best result.
FitOutcome fitModel(const FitData& fit, const ModelSpec& model, const std::vector<std::vector<double>>& starts,
                    int max_iterations);

}  // namespace gap
}  // namespace nursing_bed
