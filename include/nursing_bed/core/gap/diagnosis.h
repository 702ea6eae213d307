// The sim-to-real gap diagnosis (doc/formats/gap_report.md): where the nominal model and the recorded runs
// part, which candidate effect (gap/effects.h) explains it, and how far the gap shrinks on runs
// withheld from fitting. ROS-free; `gap diagnose` is its command line and doc/gap_diagnosis.md
// explains the method and its decisions.
#pragma once

#include <cmath>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "nursing_bed/core/gap/calibration.h"
#include "nursing_bed/core/gap/localisation.h"
#include "nursing_bed/core/gap/replay.h"
#include "nursing_bed/core/gap/run_data.h"
#include "nursing_bed/core/physics/cell_model.h"

namespace nursing_bed {

/// Knobs of the diagnosis. The defaults are the documented method; tests change little else
/// than `threads` and `progress`.
struct DiagnosisOptions {
  /// Effects to try (canonical candidate names); empty: every candidate of the catalogue.
  std::vector<std::string> candidates;
  /// Pairs tried: each of this many best singles (by BIC) with every other single (0: no pairs).
  int pair_pool = 1;
  /// Residuals enter the fits at about this rate (runs are replayed at their full rate).
  double fit_sample_hz = 10.0;
  /// Largest integration step while fitting (the run's sample interval if that is shorter) and
  /// the integrator's relative tolerance then; the final replays use the cell's own settings.
  double fit_time_step_s = 0.01;
  double fit_relative_tolerance = 3.0e-4;
  int max_iterations = 25;  ///< Levenberg-Marquardt iterations per candidate
  int threads = 2;          ///< candidate fits in parallel

  // Calibration (doc/gap_calibration.md): the model's own parameters before any effect.
  bool calibrate = true;  ///< false: the effects on top of the nominal model alone (as before calibration)
  /// Cell parameters to calibrate (calibrationCatalog() names); empty: defaultCalibrationParams().
  std::vector<std::string> calibration_params;
  /// This many best single candidates (by BIC on top of the calibration; then the best pair) are
  /// refitted with the calibrated parameters free as well, so that calibration and effects settle
  /// together; the pairs are chosen after that.
  int joint_pool = 3;
  /// ... unless their chi2/n is already at most this (within the noise: nothing left to settle).
  double joint_refit_chi2 = 1.1;
  /// A calibrated move counts when |fitted - nominal| exceeds this many standard errors and its
  /// chi2 gain, (move / SE)^2, exceeds ln n (BIC's price) by significant_bic_drop, as an effect's
  /// must (about 5.3 SE with a few thousand residuals).
  double calibration_z = 2.0;

  // Decisions (doc/gap_diagnosis.md). chi2/n is the mean squared whitened residual: residuals
  // in units of the noise floor (sensor noise, replay accuracy, and the flow meter's noise that
  // the replay integrates into a random walk of the gas mass), decorrelated (that walk is shared
  // by all later samples). About 1 for a model that fits.
  /// A candidate is significant when it lowers BIC by more than this ...
  double significant_bic_drop = 20.0;
  /// ... and lowers chi2/n by at least this much (the replay's own numerical noise, changes of
  /// the integrator's step sequence, stays below it).
  double min_chi2_drop = 0.03;
  /// The nominal model fits "within the noise" up to this chi2/n (about 1 +- 0.05 on clean data).
  double within_noise_chi2 = 1.5;
  /// A significant candidate explains the gap if on the fit runs it leaves at most this chi2/n,
  /// the same "within the noise" as for the nominal model (synthetic data leaves 0.9-1.05;
  /// recordings of the simulated bed, whose clocks jitter, up to 1.3) ...
  double explained_chi2 = 1.5;
  /// ... or removes at least this share of the nominal model's excess over 1 (a gap hundreds of
  /// noise floors deep, where the fit's integration differs from the rig's by more than the
  /// noise); and on the withheld runs it leaves at most withheld_chi2 or removes at least
  /// withheld_gap_removed of their excess. Else the gap is "unexplained".
  double explained_excess_removed = 0.995;
  double withheld_chi2 = 3.0;
  double withheld_gap_removed = 0.99;
  /// ... and it must lower the withheld runs' chi2 (whitened, summed) by at least this: their
  /// likelihood rises by e^(gain/2), about 150 : 1 at 10, with no parameter fitted to them. A
  /// fit that only bends the model onto the fit runs' noise or artefacts (a sensor lag of 50 us
  /// fitted to a lift-off spike at 50 Hz) gains nothing there.
  double min_withheld_gain = 10.0;
  /// Two candidates whose BIC on the fit runs differ by less than this are a near tie (BIC
  /// differences below 10 are not "very strong" evidence): the withheld runs, which no fit has
  /// seen, decide between them when one lowers their chi2 by min_withheld_gain more.
  double near_tie_bic = 10.0;
  /// A pair is named over one of its singles that fits the fit runs within the noise when the
  /// withheld runs, which no fit has seen, show what the single misses: it leaves their chi2
  /// above the noise by more than 3 of its standard deviations (sqrt(2 n)), and the pair removes
  /// at least this share of that excess (and min_withheld_gain).
  double pair_withheld_share = 0.5;
  /// Name the explanations within near_tie_bic of the verdict's that no run here tells from it,
  /// and propose the gap synth run that would (identifiability.h).
  bool propose_runs = true;
  /// Fitted parameters may lie this factor outside their plausible range (log-scale ones; linear
  /// ones this many range widths) before the fit is called implausible.
  double plausible_slack = 3.0;

  // Discovery (doc/gap_diagnosis.md, "Discovery"): when the verdict is "unexplained", a sparse
  // correction to the balance equations from a dictionary of state functions.
  bool discover = true;
  int discovery_resamples = 20;            ///< block bootstraps of the fit runs' residuals
  double discovery_stability = 0.8;        ///< share of the resamples that must select a term
  int discovery_max_terms = 3;             ///< per resample
  double discovery_withheld_shrink = 0.1;  ///< least share of the withheld nrmse the terms remove

  // The model-form floor (doc/gap_real_recordings.md): a recording of real hardware never fits
  // the model to the noise. "on": when no candidate explains the gap by the rules above, the
  // calibrated nominal model's chi2/n on the fit runs is taken as the floor of the model's form,
  // chi2 is counted in units of it, and a candidate is named when it is significant in those
  // units and removes at least floor_removed of the calibrated model's chi2 on the fit runs and
  // on the withheld runs. "auto": on when every run was imported from a recording (gap import's
  // import_mapping metadata); synthetic and bag runs keep the rules above alone. "off": never.
  std::string model_floor = "auto";
  double floor_removed = 0.5;

  /// Called with one line per step ("fitting leak ... 3/7"). May be empty.
  std::function<void(const std::string&)> progress;
  /// The fits' progress lines also carry their replays and the solver's report.
  bool verbose = false;
  /// Called after each progress line of `gap diagnose` with the elapsed time and an estimate of
  /// the time left ("41 s elapsed, about 2 min left"). May be empty.
  std::function<void(const std::string&)> status;
};

/// One fitted model: nominal plus `effects`.
struct CandidateFit {
  std::vector<std::string> effects;      ///< canonical names, catalogue order
  std::map<std::string, double> params;  ///< fitted parameters (SI, catalogue keys)
  /// Calibrated cell parameters this model was fitted with (moved ones; calibration.h names).
  std::map<std::string, double> calibration;
  bool joint = false;                     ///< refitted with the calibrated parameters free
  double chi2 = 0.0;                      ///< fit runs, sum of squared noise-scaled residuals
  double bic_delta = 0.0;                 ///< BIC minus the nominal model's (negative: better)
  double fit_nrmse = 0.0;                 ///< on the fit runs (the report's nrmse)
  double withheld_nrmse = 0.0;            ///< on the withheld runs (NaN when there are none)
  double withheld_chi2_per_sample = NAN;  ///< whitened, on the withheld runs (NaN: none)
  bool plausible = true;                  ///< every parameter within its (slackened) plausible range
  /// Implausible by a magnitude beyond that range only (not a timing below resolution).
  bool beyond_plausible = false;
  bool ok = true;       ///< false: the model failed on some run
  std::string message;  ///< why not ok, or notes
  int evaluations = 0;  ///< replays of the fit-run set spent on it
};

/// Per-run numbers for the report.
struct RunSummary {
  std::string name;
  std::string role;  ///< fit or withheld
  double load_n = 0.0;
  double duration_s = 0.0;
  double noise_p_pa = 0.0, noise_h_m = 0.0;
  RunResidual before, after;  ///< nominal and verdict model
};

/// Traces of one run for plots: measured, nominal and verdict-model readings.
struct RunTrace {
  std::string name;
  std::string role;
  std::vector<double> t_s, mdot_in_kg_s, p_meas_pa, h_meas_m, p_nominal_pa, h_nominal_m, p_after_pa, h_after_m;
  std::vector<RunPhase> phases;
  /// Each named cause alone on the final calibration (its figure: data, model, model + cause).
  std::vector<std::string> causes;
  std::vector<std::vector<double>> p_cause_pa, h_cause_m;
};

/// One line of the validation statement (ASME V&V 20; gap/validation.h): a signal ("pressure"
/// [Pa] or "height" [m]) over one phase and load, on the samples the fits use (fit and withheld
/// runs). Uncertainties are standard ones, RMS over those samples.
struct ValidationRow {
  std::string signal, phase;
  double load_n = 0.0;
  int samples = 0;
  double e_mean = 0.0, e_rms = 0.0;  ///< E = simulated - measured
  double u_data = 0.0, u_num = 0.0, u_input = 0.0;
  double u_val = 0.0;  ///< sqrt(u_data^2 + u_num^2 + u_input^2)
};

/// Two explanations the runs cannot tell apart, and the run that would (identifiability.h).
struct Confusion {
  std::string a, b;  ///< the winner and its rival (effects joined by '+', or a calibrated parameter)
  std::map<std::string, double> b_params;               ///< the rival's fitted (or least-squares) parameters
  double bic_a = NAN, bic_b = NAN;                      ///< fit runs, against the baseline model
  double withheld_chi2_a = NAN, withheld_chi2_b = NAN;  ///< whitened, summed (NaN: nothing withheld)
  double correlation = NAN;                             ///< of their whitened changes to the fit residuals
  double fit_separation_chi2 = NAN;                     ///< their replays' difference on the fit runs, in noise floors
  bool proposed = false;                                ///< a run of the grid separates them
  double load_n = NAN;                                  ///< the proposed run (SynthRunPlan)
  std::string flow;
  double rise_scale = 1.0;
  double separation_chi2 = NAN;  ///< their replays' difference on it, in noise floors
};

// size: a plain record of every figure and table the diagnosis reports
struct DiagnosisReport {
  std::string dataset;
  DiagnosisOptions options;  ///< the thresholds the decision used
  std::vector<std::string> fit_runs, withheld_runs;
  bool roles_chosen = false;  ///< true: no roles were given, the diagnosis chose them
  double noise_p_pa = 0.0, noise_h_m = 0.0;
  std::vector<GapShare> localization;
  /// Where in time the nominal model and each run part (re-anchored windows; localisation.h).
  std::vector<GapEvent> events;
  /// The nominal model's comparison error and validation uncertainty per signal, phase and load.
  std::vector<ValidationRow> validation;
  double nominal_chi2_per_sample = 0.0;  ///< fit runs, in noise-floor units
  double nominal_fit_nrmse = 0.0;
  double nominal_withheld_chi2_per_sample = NAN;  ///< whitened, withheld runs (NaN: none)
  int fit_samples = 0;                            ///< residuals in the fits (both signals)
  std::vector<CandidateFit> candidates;           ///< best (lowest BIC) first
  CalibrationSummary calibration;                 ///< the verdict model's calibration
  std::string calibrated_yaml;                    ///< the complete calibrated parameter file (calibration.file)
  bool pressure_only = false;                     ///< no run has a height reading
  std::string status;                             ///< none, calibrated, explained, discovered, unexplained
  std::vector<std::string> verdict_effects;
  std::map<std::string, double> verdict_params;
  /// The named channel distortions in words, with standard errors ("height: gain -4.1 % ± 0.3 %").
  std::vector<std::string> verdict_distortions;
  /// Status "discovered": each term as an equation in units with its stability
  /// ("plate force: −420 N·s²/m² · |v|v, stable in 19 of 20 resamples").
  std::vector<std::string> discovered;
  /// Explanations within a few BIC of the verdict's that no run here tells from it, each with the
  /// run that would.
  std::vector<Confusion> confusions;
  std::vector<std::string> reasons;  ///< the decision in words, one line each
  // Shrinkage on the withheld runs: nominal vs verdict model (equal when nothing is named).
  double withheld_before = 0.0, withheld_after = 0.0;
  double withheld_p_before = 0.0, withheld_p_after = 0.0, withheld_h_before = 0.0, withheld_h_after = 0.0;
  double withheld_calibrated = NAN;  ///< the calibrated model alone (no effects) on the withheld runs
  /// The final model's (calibration and effects) whitened chi2/n on the withheld runs (NaN: none).
  double withheld_chi2_after = NAN;
  /// The withheld runs' gap above the noise floor, in noise floors: sqrt(chi2/n - 1) (0 within
  /// the noise), before (nominal) or after. No model leaves less than the floor (sensor noise
  /// and replay accuracy), so where the gap is a few floors deep the nrmse shrinks little while
  /// this falls to 0.
  double withheldGapInFloors(bool after) const;
  std::vector<RunSummary> runs;
  std::vector<RunTrace> traces;
  double elapsed_s = 0.0;
};

/// What the decision needs of the nominal model.
struct NominalScore {
  double chi2 = 0.0;                      ///< fit runs, whitened, summed
  int fit_residuals = 0;                  ///< n of the BIC
  double withheld_chi2_per_sample = NAN;  ///< whitened, withheld runs
  int withheld_residuals = 0;             ///< 0: nothing withheld
  double withheld_nrmse = NAN;            ///< for the reasons
};

struct Verdict {
  std::string status;                ///< none, explained, unexplained
  int winner = -1;                   ///< index of the named candidate; -1: none named
  std::vector<std::string> reasons;  ///< the decision in words, one line each
};

/// The decision of doc/gap_diagnosis.md ("Decisions") over fitted `candidates` (lowest BIC
/// first, as DiagnosisReport::candidates): significance, holding up on fit and withheld runs,
/// pairs only where no single explains the gap, near ties decided by the withheld runs.
Verdict decideVerdict(const std::vector<CandidateFit>& candidates, const NominalScore& nominal,
                      const DiagnosisOptions& options);

/// The decision above the model-form floor (DiagnosisOptions::model_floor): the floor is the
/// calibrated nominal model's chi2/n (fit runs; withheld runs apart), at least 1; the first
/// candidate in BIC order (singles before pairs) that lowers BIC by significant_bic_drop with
/// chi2 counted in floor units, and removes floor_removed of the floor's chi2 on the fit runs
/// and on the withheld runs, is named ("explained"); else "none" (what remains is the model's
/// form). The reasons give the floor and each significant candidate's share removed.
Verdict decideVerdictAboveFloor(const std::vector<CandidateFit>& candidates, const NominalScore& nominal,
                                const DiagnosisOptions& options);
/// Whether `options.model_floor` applies to runs whose metadata are `metas` ("auto": every run
/// imported, i.e. with import_mapping metadata). Throws std::invalid_argument for another word.
bool modelFloorApplies(const DiagnosisOptions& options,
                       const std::vector<const std::map<std::string, std::string>*>& metas);

/**
 * Diagnoses `runs` (each with a role "fit"/"withheld", or all without one; then about a
 * quarter, spread over the loads, is withheld and the report says so) against the nominal
 * model of `params`. Throws std::invalid_argument for unusable input: no runs, a run whose
 * nominal replay fails, fewer than 2 runs with roles missing, no fit run, an unknown candidate.
 */
DiagnosisReport diagnoseRuns(std::vector<RunData> runs, const CellParams& params, const DiagnosisOptions& options,
                             const std::string& dataset_name = "");

/**
 * Calibrates the model's own parameters (options.calibration_params, or the defaults for these
 * runs) on the fit runs, without looking for effects: the report has the calibration, status
 * `calibrated` (the calibrated model fits within the noise and holds up on the withheld runs),
 * `none` (nothing moved) or `unexplained` (a gap calibration does not remove), the withheld
 * runs' nrmse before and after, and the calibrated parameter file. Throws as diagnoseRuns().
 */
DiagnosisReport calibrateRuns(std::vector<RunData> runs, const CellParams& params, const DiagnosisOptions& options,
                              const std::string& dataset_name = "");

/// report.json exactly as doc/formats/gap_report.md describes it (plus nothing else).
std::string reportJson(const DiagnosisReport& report);
/// report.md: the three answers in words and tables, and the figures written beside it.
std::string reportMarkdown(const DiagnosisReport& report);
/// Writes DIR/report.json, DIR/report.md and DIR/traces/<run>.csv (inputs of the plots);
/// throws std::runtime_error naming the file that cannot be written.
void writeReportFiles(const std::string& dir, const DiagnosisReport& report);

}  // namespace nursing_bed
