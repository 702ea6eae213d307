// The stages of diagnoseRuns() (doc/gap_diagnosis.md), each a function of its own so that it can
// be tested and reused (calibration runs the same stages on other models):
//   prepareRuns      roles, each run's noise, the closed inlet's flow set to zero
//   replayNominal    the nominal replay of every run, per-run numbers, where the gap lies
//   buildNoiseModel  the fit and withheld runs' samples with their noise floor; nominal chi2
//   fitCandidates    every single candidate from a grid, then pairs of the best singles
//   scoreCandidates  BIC against the nominal model, nrmse and withheld chi2 of each, sorted
//   decideVerdict    (diagnosis.h) which candidate, if any, explains the gap
//   shrinkage        the verdict model's replays: traces and the withheld runs' nrmse
#pragma once

#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "nursing_bed/core/gap/diagnosis.h"
#include "nursing_bed/core/gap/fit_model.h"
#include "nursing_bed/core/gap/noise_model.h"

namespace nursing_bed {
namespace gap {

/// The runs as the fits see them, with their roles and noise.
struct PreparedRuns {
  std::vector<RunData> runs;                       ///< inflow set to 0 where the closed inlet read noise
  std::vector<RunNoise> noises;                    ///< each run's sensor noise, as measured
  std::vector<std::vector<double>> measured_flow;  ///< each run's inflow as measured (traces, meter noise)
  std::vector<std::size_t> fit, withheld;          ///< indices into runs, by role
  bool roles_chosen = false;                       ///< no run had a role: chooseRoles() chose them
  int gated_runs = 0;                              ///< runs whose closed-inlet flow was set to 0

  std::vector<const RunData*> select(const std::vector<std::size_t>& indices) const;
};

/// About a quarter of the runs withheld, spread over the loads: sorted by load then name, every
/// fourth starting with the second.
void chooseRoles(std::vector<RunData>* runs);

/// Checks the roles (fit, withheld, or none at all), chooses them where no run has one (runs
/// without one among runs with one are fit runs), measures each run's noise and sets the closed
/// inlet's noise-around-zero flow to 0. Throws std::invalid_argument: no runs, a bad role, one
/// run without roles, no fit run.
PreparedRuns prepareRuns(std::vector<RunData> runs);

/// The candidate list of `options` (every catalogue candidate when empty); throws
/// std::invalid_argument naming an unknown one.
std::vector<std::string> candidateList(const DiagnosisOptions& options);

/// The nominal replay of every run; fills `report`'s runs (before), noise and localization.
/// Throws std::invalid_argument with the replay's message when one fails.
std::vector<Replay> replayNominal(const PreparedRuns& prepared, const CellParams& params, const DiagnosisOptions& options,
                                  DiagnosisReport* report);

/// Fit and withheld runs prepared for the fits, and the nominal model's score on them.
struct NoiseModel {
  FitData fit, held;     ///< fit.params: the cell with the fit's integration settings
  double chi2_nominal = 0.0;                  ///< fit runs, whitened, summed
  double withheld_chi2_per_sample = NAN;      ///< NaN: nothing withheld
  int fitResidualCount() const { return fit.residualCount(); }
  int heldResidualCount() const { return held.residualCount(); }
};

/// Prepares every run (prepareFitRun) and scores the nominal model. The FitData point into
/// `prepared`, which must outlive the result.
NoiseModel buildNoiseModel(const PreparedRuns& prepared, const CellParams& params, const DiagnosisOptions& options);

/// A fitted candidate model.
struct ModelFit {
  ModelSpec model;
  FitOutcome outcome;
};

/// Fits every single candidate from a grid, then the pairs among the `options.pair_pool` best
/// singles (by BIC) from the singles' fits. Singles first, in `candidates` order, then the pairs.
/// `progress` (may be empty) gets a line per fit.
std::vector<ModelFit> fitCandidates(const NoiseModel& noise, const std::vector<std::string>& candidates,
                                    const DiagnosisOptions& options,
                                    const std::function<void(const std::string&)>& progress);

/// A candidate's report entry and the model behind it.
using ScoredCandidate = std::pair<CandidateFit, ModelSpec>;

/// BIC (chi2 + k ln n) against the nominal model, plausibility, nrmse on fit and withheld runs
/// and the withheld runs' chi2 of every fit; sorted by BIC, failed fits last.
std::vector<ScoredCandidate> scoreCandidates(const std::vector<ModelFit>& fits, const PreparedRuns& prepared,
                                             const NoiseModel& noise, const CellParams& params,
                                             const DiagnosisOptions& options);

/// Replays every run with `effects` (reusing `nominal` when there are none) and fills
/// `report`'s traces, per-run residuals after, and the withheld runs' nrmse before and after.
void shrinkage(const PreparedRuns& prepared, const CellParams& params, const std::vector<CellEffectPtr>& effects,
               const std::vector<Replay>& nominal, const DiagnosisOptions& options, DiagnosisReport* report);

// ---- small helpers shared by the stages ---------------------------------------------------------

double median(std::vector<double> v);

/// Mean nrmse (and per signal) of a set of runs under a model.
struct SetResidual {
  double total = NAN, p = NAN, h = NAN;
  bool ok = true;
};

SetResidual setResidual(const std::vector<const RunData*>& runs, const CellParams& params,
                        const std::vector<CellEffectPtr>& effects);

/// Runs `task(i)` for i in [0, count) on `threads` workers.
void parallelFor(int count, int threads, const std::function<void(int)>& task);

/// `v` with `precision` significant digits.
std::string fmt(double v, int precision = 3);

}  // namespace gap
}  // namespace nursing_bed
