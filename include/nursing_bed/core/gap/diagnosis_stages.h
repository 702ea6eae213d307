// The stages of diagnoseRuns() (doc/gap_diagnosis.md), each a function of its own so that it can
// be tested and reused (calibration runs the same stages on other models):
//   prepareRuns      roles, each run's noise, the closed inlet's flow set to zero
//   replayNominal    the nominal replay of every run, per-run numbers, where the gap lies
//   buildNoiseModel  the fit and withheld runs' samples with their noise floor; nominal chi2
//   fitCandidates    every single candidate from a grid, then the best single paired with each other
//   scoreCandidates  BIC against the nominal model, nrmse and withheld chi2 of each, sorted
//   decideVerdict    (diagnosis.h) which candidate, if any, explains the gap
//   shrinkage        the verdict model's replays: traces and the withheld runs' nrmse
#pragma once

#include <cmath>
#include <functional>
#include <map>
#include <set>
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
/// `candidates` less those that assume a structure other than that of `nominal`
/// (EffectSpec::structure), each left out with a line in `notes`.
std::vector<std::string> candidatesForStructure(const std::vector<std::string>& candidates, const CellParams& nominal,
                                                std::vector<std::string>* notes);

/// The nominal replay of every run; fills `report`'s runs (before), noise and localization.
/// Throws std::invalid_argument with the replay's message when one fails.
std::vector<Replay> replayNominal(const PreparedRuns& prepared, const CellParams& params,
                                  const DiagnosisOptions& options, DiagnosisReport* report);

/// Fit and withheld runs prepared for the fits, and the nominal model's score on them.
struct NoiseModel {
  FitData fit, held;                      ///< fit.params: the cell with the fit's integration settings
  double chi2_nominal = 0.0;              ///< fit runs, whitened, summed
  double withheld_chi2_per_sample = NAN;  ///< NaN: nothing withheld
  /// The model the candidates are compared with: the nominal one, or after rebaseNoiseModel()
  /// the calibrated one (these calibrated values, its chi2 on the fit and withheld runs).
  std::map<std::string, double> baseline_calibration;
  double baseline_chi2 = 0.0;
  double baseline_withheld_chi2_per_sample = NAN;
  /// The n of chi2/n and BIC (residuals that carry a reading; FitData::informativeCount()).
  int fitResidualCount() const { return fit.informativeCount(); }
  int heldResidualCount() const { return held.informativeCount(); }
};

/// Prepares every run (prepareFitRun) and scores the nominal model. The FitData point into
/// `prepared`, which must outlive the result.
NoiseModel buildNoiseModel(const PreparedRuns& prepared, const CellParams& params, const DiagnosisOptions& options);

/// A fitted candidate model.
struct ModelFit {
  ModelSpec model;
  FitOutcome outcome;
};

/// Catalogue position of an effect (pairs list their effects in catalogue order, so that their
/// parameters line up with the singles' fits): the physical catalogue's, then the distortions'.
std::ptrdiff_t catalogPosition(const std::string& name);
/// An effect of the physical catalogue (effectCatalog(); its two channel-distortion members
/// included), not one of the distortion catalogue's.
bool isPhysicalCatalogEffect(const std::string& name);
/// The pair of effects `a` and `b` in catalogue order, on the cell with `calibration` fixed.
ModelSpec pairSpec(const std::string& a, const std::string& b, const std::map<std::string, double>& calibration);
/// The starts of a pair's fit: each single's fitted coordinates, and each effect also at the
/// middle of its plausible range and near off (its lower bound), in every combination. A single
/// fitted alone soaks up part of the other effect's signature (a leak fitted alone also bends to
/// the heat transfer's relaxation), so its own fit can be a poor start for the pair.
std::vector<std::vector<double>> pairStarts(const ModelSpec& pair, const ModelFit& a, const ModelFit& b);

/// Fits every single candidate from a grid, then pairs from the singles' fits (pairsToFit: the
/// `options.pair_pool` best singles by BIC, each with every other); no pair when the best single
/// fits within options.joint_refit_chi2. Singles first, in `candidates`
/// order, then the pairs. `progress` (may be empty) gets a line per fit.
/// `after_singles` (may be empty) may refit the singles (jointly with the calibration) before
/// the pairs are chosen from them. `fitted_singles`, when given, are these singles already
/// fitted on the same baseline (the nominal cell's, when the calibration did not move): reused.
std::vector<ModelFit> fitCandidates(const NoiseModel& noise, const std::vector<std::string>& candidates,
                                    const DiagnosisOptions& options,
                                    const std::function<void(const std::string&)>& progress,
                                    const std::function<void(std::vector<ModelFit>*)>& after_singles = {},
                                    const std::vector<ModelFit>& fitted_singles = {});

/// The pairs fitCandidates() fits, as indices into `fits` (singles; `order` ranks them, best
/// first): each of the `pool` best ok singles (and the best physical effect, where those are all
/// channel distortions) with every ok single ranked below it (forward
/// selection: a second effect whose signature the first one hides ranks low alone, as a
/// pressure sensor lag does beside a flow meter's bias; a pair of two poor singles is not
/// tried: its replays are the slowest and it rarely fits). None when the best already fits
/// within `within_chi2` per residual (n residuals).
std::vector<std::pair<int, int>> pairsToFit(const std::vector<ModelFit>& fits, const std::vector<int>& order, int pool,
                                            int n, double within_chi2);

// ---- calibration (calibration_stage.cpp) ------------------------------------------------------

/// A model fitted with calibrated cell parameters (alone, or with effects) and the judgement of
/// each calibrated parameter.
struct CalibrationFit {
  ModelFit fit;                 ///< every requested parameter free
  CalibrationSummary summary;   ///< moved parameters at their values, the others nominal
  ModelSpec moved_model;        ///< the moved calibration parameters (and the effects) only
  std::vector<double> moved_u;  ///< their fit (equals fit when every parameter moved)
  double moved_chi2 = NAN;      ///< fit runs, whitened, summed: the calibrated model
};

/// Standard errors (Ceres covariance, scaled by chi2/n where above 1), correlations, the groups
/// the runs cannot tell apart and which calibrated parameters moved (|move| > z SE and
/// (move/SE)^2 > ln n + significant_bic_drop) of a fitted model. Fills summary.parameters (value = fitted where moved).
CalibrationSummary judgeCalibration(const NoiseModel& noise, const ModelFit& fit, const DiagnosisOptions& options);

/// Calibrates `names` alone on the fit runs: Levenberg-Marquardt from the nominal values, each
/// move judged, the moved ones refitted alone; nothing moves unless the calibrated model lowers
/// BIC by significant_bic_drop and chi2/n by min_chi2_drop against the nominal model.
CalibrationFit calibrateModel(const NoiseModel& noise, const std::vector<std::string>& names,
                              const DiagnosisOptions& options, const std::function<void(const std::string&)>& progress);

/// Refits `candidate` (effects fitted on top of the calibration `base`) with every calibrated
/// parameter free as well, from both fits (and from `uncalibrated`, the same effects fitted on
/// the nominal cell, if given); the moved ones (judged in the joint fit) are kept. A refit that
/// matters only if it overtakes `overtake_chi2` stops once it cannot (fitModel()): then its
/// fit.outcome.stopped is set and nothing is judged.
CalibrationFit refitJointly(const NoiseModel& noise, const ModelFit& candidate, const CalibrationFit& base,
                            const DiagnosisOptions& options, const ModelFit* uncalibrated = nullptr,
                            double overtake_chi2 = INFINITY);

/// Calibration must not swallow an effect: the parameters are constant over all runs, the
/// effects are dynamic, and the withheld runs judge both. Drops `c`'s moves (and says why in its
/// notes) when an effect alone, fitted on the nominal cell (`uncalibrated`) with plausible
/// parameters, fits the fit runs better (BIC, its parameters against the moved ones) and lowers
/// the withheld runs' chi2 below the calibrated model's by min_withheld_gain. True if dropped.
bool dropCalibrationForEffect(const NoiseModel& noise, const std::vector<ModelFit>& uncalibrated,
                              const DiagnosisOptions& options, CalibrationFit* c);

/// Makes the calibrated model (the nominal cell with `calibration`, whose chi2 on the fit runs is
/// `chi2`) the baseline the candidates are fitted on and compared with; scores the withheld runs.
void rebaseNoiseModel(NoiseModel* noise, const std::map<std::string, double>& calibration, double chi2);

/// The cell parameters to calibrate: options.calibration_params (checked against the runs and
/// the structure of `nominal`), or defaultCalibrationParams(); none when options.calibrate is
/// false. Throws std::invalid_argument.
std::vector<std::string> calibrationList(const PreparedRuns& prepared, const DiagnosisOptions& options,
                                         const CellParams& nominal);

/// Indices into `fits` of the fits of `effects` effects (failed ones left out) that
/// refitBestJointly() refits: the `pool` best by BIC (chi2 + k ln n), then every other one that
/// contains an effect of `also`; best first.
/// `on_nominal[i]`, when given and not null, is fit i's counterpart fitted on the nominal cell
/// (when the calibration moved): a fit ranks by the better of the two, since an effect the
/// calibration imitated in part fits badly on top of it and well on the nominal cell.
std::vector<int> jointRefitOrder(const std::vector<ModelFit>& fits, std::size_t effects, int pool,
                                 const std::set<std::string>& also, double log_n,
                                 const std::vector<const ModelFit*>& on_nominal = {});

/// What refitBestJointly() did.
struct JointRefits {
  /// The joint fits' calibration summaries, by joinNames(effects).
  std::map<std::string, CalibrationSummary> summaries;
  /// Effects of the refits whose chi2 fell significantly with the calibration free (its gain,
  /// scaled by chi2/n where above 1, beyond ln n + significant_bic_drop): the calibration alone
  /// had bent to part of their signature, so fits on top of it are biased for them.
  std::set<std::string> moved_calibration;
};

/// Refits the `pool` best fits of `effects` effects (by BIC), and every fit of `effects` effects
/// that contains one of `also` (the singles that moved the calibration: a pair fitted on the
/// calibration they bent is biased however it ranks), whose chi2/n is above
/// options.joint_refit_chi2, jointly with the calibration (refitJointly, also started from the
/// fit's counterpart in `uncalibrated`, the singles fitted on the nominal cell, which rank the
/// fits too: jointRefitOrder); replaces each by its joint fit where that fits better. When the
/// best is within joint_refit_chi2 already, only it is refitted (if the calibration moved) and the
/// others not at all; else the best first: when it lands within joint_refit_chi2 the others are
/// not refitted, and otherwise each of them stops once, at its pace, it could not overtake the
/// best (they decide nothing else) and stays as it was. The best's own refit always runs in full:
/// its point ranks it for the pairs, and a solve's pace over a few iterations does not forecast
/// where it ends.
JointRefits refitBestJointly(const NoiseModel& noise, const CalibrationFit& base, std::vector<ModelFit>* fits,
                             std::size_t effects, int pool, const DiagnosisOptions& options,
                             const std::function<void(const std::string&)>& progress,
                             const std::set<std::string>& also = {}, const std::vector<ModelFit>& uncalibrated = {});

/// The verdict with calibration: "none" with moved parameters becomes "calibrated" when the
/// calibrated model holds up on the withheld runs (within the noise or 99 % of their gap removed,
/// and their chi2 lower by min_withheld_gain), else the moves are dropped; reasons added.
/// `above_floor` (a recording judged above its model-form floor, decideVerdictAboveFloor()):
/// removing floor_removed of the withheld runs' chi2 also holds up.
void settleCalibratedStatus(const NoiseModel& noise, const DiagnosisOptions& options, DiagnosisReport* report,
                            bool above_floor = false);
/// "none" holds only where the withheld runs agree: a nominal model within the noise on the fit
/// runs that leaves the withheld runs above options.withheld_chi2 (the bar a named effect must
/// meet there) means the fit runs do not exercise what the withheld runs show, so the status
/// becomes "unexplained" with the reason. Not `above_floor` (its "none" is the model's form).
void settleNoneOnWithheld(const NoiseModel& noise, const DiagnosisOptions& options, DiagnosisReport* report,
                          bool above_floor);

/// The calibrated model alone: its nrmse on fit and withheld runs, and the calibrated parameter
/// file (report->calibrated_yaml; the cell's own settings with the moved values).
void calibratedOutcome(const PreparedRuns& prepared, const NoiseModel& noise, const CellParams& params,
                       DiagnosisReport* report);

/// A candidate's report entry and the model behind it.
using ScoredCandidate = std::pair<CandidateFit, ModelSpec>;

/// BIC (chi2 + k ln n) against the nominal model, plausibility, nrmse on fit and withheld runs
/// and the withheld runs' chi2 of every fit; sorted by BIC, failed fits last.
std::vector<ScoredCandidate> scoreCandidates(const std::vector<ModelFit>& fits, const PreparedRuns& prepared,
                                             const NoiseModel& noise, const CellParams& params,
                                             const DiagnosisOptions& options);

/// Whitened chi2 per residual of the withheld runs under `calibration` and `effects` (NaN when
/// nothing is withheld or the replay failed).
double withheldChi2(const NoiseModel& noise, const std::map<std::string, double>& calibration,
                    const std::vector<CellEffectPtr>& effects);

/// Replays every run with `effects` (reusing `nominal` when there are none) and fills
/// `report`'s traces, per-run residuals after, and the withheld runs' nrmse before and after.
/// `params` is the nominal cell with `calibration` (the nominal replays are reused when both
/// it and `effects` are empty).
void shrinkage(const PreparedRuns& prepared, const CellParams& params, const std::map<std::string, double>& calibration,
               const std::vector<CellEffectPtr>& effects, const std::vector<Replay>& nominal,
               const DiagnosisOptions& options, DiagnosisReport* report);

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
