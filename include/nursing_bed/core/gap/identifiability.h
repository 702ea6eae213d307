// Identifiability and the next experiment: the explanations the diagnosis's runs cannot tell
// apart (another candidate, or a calibrated parameter of the cell, fitting within a few BIC of
// the winner on the fit runs with the withheld runs undecided), and the run that would: the
// gap synth run (load, hold height, rise) on which the two, each replayed, differ most in noise
// units. ROS-free (doc/gap_diagnosis.md, "What the runs cannot tell apart").
#pragma once

#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Dense>

#include "nursing_bed/core/gap/diagnosis.h"
#include "nursing_bed/core/gap/diagnosis_stages.h"
#include "nursing_bed/core/gap/synth.h"

namespace nursing_bed {
namespace gap {

/// One explanation of the gap: a cell (calibrated where it moved) with effects.
struct Explanation {
  std::string name;  ///< "pressure_gain", "leak+heat_transfer", or a calibrated parameter's name
  CellParams params;
  std::vector<CellEffectPtr> effects;
  /// The same with each of its parameters moved a small step: the directions a refit may take.
  std::vector<std::pair<CellParams, std::vector<CellEffectPtr>>> moved;
  /// Columns: the whitened fit residuals' change along each of `moved` (what a refit costs there).
  Eigen::MatrixXd fit_sensitivity;
  double chi2 = 0.0;           ///< fit runs, whitened, summed
  double bic_delta = 0.0;      ///< against the baseline model, as CandidateFit::bic_delta
  double held_chi2 = NAN;      ///< withheld runs, whitened, summed (NaN: none)
  std::vector<double> change;  ///< its whitened fit residuals less the baseline's
};

/// The gap synth runs a proposal is chosen from: every load x both flows x these rises, on the
/// standard protocol's timing (driven through the valves where the dataset's runs are).
struct ExperimentGrid {
  std::vector<double> loads_n{0.6, 5.0, 10.6, 15.6, 20.6, 30.0, 40.0};
  std::vector<std::string> flows{"low", "high"};
  std::vector<double> rise_scales{1.0, 3.0};
};

/// The proposal for one confused pair: the run, and how far apart the two put its readings.
struct ProposedExperiment {
  SynthRunPlan run;              ///< load_n, flow, rise_scale (gap synth --add-run)
  double separation_chi2 = 0.0;  ///< sum of squared differences of the two replays, in noise floors
};

/// Finds the explanations within `options.near_tie_bic` of `winner` on the fit runs that the
/// withheld runs do not tell from it (chi2 within `options.min_withheld_gain`): other scored
/// candidates (not those holding all of the winner's effects) and each calibration parameter
/// not moved already, fitted alone on the baseline cell (a few Gauss-Newton steps). For each
/// (at most three), the run of `grid` that separates it from the winner best (proposeExperiment(),
/// recorded at the dataset's pressure noise `noise_p_pa`), proposed where that leaves at least
/// `options.significant_bic_drop` of chi2 between them.
std::vector<Confusion> findConfusions(const std::vector<ScoredCandidate>& scored, int winner,
                                      const PreparedRuns& prepared, const NoiseModel& noise, const CellParams& params,
                                      const std::vector<std::string>& calibrated, const DiagnosisOptions& options,
                                      double noise_p_pa, const ExperimentGrid& grid = {});

/// What a proposed run is recorded with: the dataset's kind of run and its noise floor.
struct ProposalSetting {
  bool valve_driven = false;  ///< driven through the valves (no flow meter)
  bool has_height = true;
  double noise_p_pa = 30.0;      ///< the dataset's pressure noise (the height's scales with it)
  double supply_gauge_pa = NAN;  ///< what the dataset's supply gauge reads (valve-driven runs)
  double fit_sample_hz = 10.0;
  int threads = 1;
  double min_separation_chi2 = 20.0;  ///< a run is proposed where it leaves at least this
};

/// The run of `grid` that separates `a` and `b` best: recorded on the nominal cell with the
/// dataset's noise and whitened by the diagnosis's noise model (`noise`'s fit settings), each
/// replayed on it, the other refitted (Gauss-Newton along its `moved` directions, paying on the
/// fit runs by its fit_sensitivity) to the first's readings; the smaller of the two chi2 left.
ProposedExperiment proposeExperiment(const Explanation& a, const Explanation& b, const CellParams& nominal,
                                     const NoiseModel& noise, const ProposalSetting& setting,
                                     const ExperimentGrid& grid);

/// The calibrated parameters the fit's covariance cannot tell apart (CalibrationSummary::
/// unidentifiable pairs of `calibrated`, not the structural ones): each alone on the calibrated
/// cell without the two, where the fit and withheld runs do not decide between them, with the
/// run of `grid` that would.
std::vector<Confusion> findCalibrationConfusions(const PreparedRuns& prepared, const NoiseModel& noise,
                                                 const CellParams& params, const std::vector<std::string>& calibrated,
                                                 const CalibrationSummary& summary, const DiagnosisOptions& options,
                                                 double noise_p_pa, const ExperimentGrid& grid = {});

/// The confusion in words, with the proposed run as a gap synth argument.
std::string describeConfusion(const Confusion& c);
/// "load_n=0.6,flow=high,rise_scale=1" (gap synth --add-run).
std::string addRunArgument(const Confusion& c);

}  // namespace gap
}  // namespace nursing_bed
