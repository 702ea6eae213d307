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

#include "nursing_bed/core/gap/diagnosis.h"
#include "nursing_bed/core/gap/diagnosis_stages.h"
#include "nursing_bed/core/gap/synth.h"

namespace nursing_bed {
namespace gap {

/// The gap synth runs a proposal is chosen from: every load x both flows x these rises, on the
/// standard protocol's timing (driven through the valves where the dataset's runs are).
struct ExperimentGrid {
  std::vector<double> loads_n{0.6, 5.0, 10.6, 15.6, 20.6, 30.0, 40.0};
  std::vector<std::string> flows{"low", "high"};
  std::vector<double> rise_scales{1.0, 3.0};
};

/// Finds the explanations within `options.near_tie_bic` of `winner` on the fit runs that the
/// withheld runs do not tell from it (chi2 within `options.min_withheld_gain`): other scored
/// candidates, each calibration parameter not moved already fitted alone on the baseline cell,
/// and the winner with another physical effect where what it adds moves the readings. For each
/// (at most three), the run of `grid` that separates it from the winner best (recorded at the
/// dataset's pressure noise `noise_p_pa`), proposed where that leaves at least
/// `options.significant_bic_drop` of chi2 between them.
std::vector<Confusion> findConfusions(const std::vector<ScoredCandidate>& scored, int winner,
                                      const PreparedRuns& prepared, const NoiseModel& noise, const CellParams& params,
                                      const std::vector<std::string>& calibrated, const DiagnosisOptions& options,
                                      double noise_p_pa, const ExperimentGrid& grid = {});

/// The calibrated parameters the fit's covariance cannot tell apart (CalibrationSummary::
/// unidentifiable pairs of `calibrated`, not the structural ones): each alone on the calibrated
/// cell without the two, where the fit and withheld runs do not decide between them, with the
/// run of `grid` that would.
std::vector<Confusion> findCalibrationConfusions(const PreparedRuns& prepared, const NoiseModel& noise,
                                                 const CellParams& params, const std::vector<std::string>& calibrated,
                                                 const CalibrationSummary& summary, const DiagnosisOptions& options,
                                                 double noise_p_pa, const ExperimentGrid& grid = {});

/// The channel distortions that fit the runs as well as the calibration's moves
/// (CalibrationSummary::distortion_ties): the moves and each distortion on the nominal cell,
/// with the run of `grid` that would tell them apart.
std::vector<Confusion> findCalibrationDistortionConfusions(const PreparedRuns& prepared, const NoiseModel& noise,
                                                           const CellParams& params,
                                                           const std::vector<std::string>& calibrated,
                                                           const CalibrationSummary& summary,
                                                           const DiagnosisOptions& options, double noise_p_pa,
                                                           const ExperimentGrid& grid = {});

/// The confusion in words, with the proposed run as a gap synth argument.
std::string describeConfusion(const Confusion& c);
/// "load_n=0.6,flow=high,rise_scale=1" (gap synth --add-run).
std::string addRunArgument(const Confusion& c);

}  // namespace gap
}  // namespace nursing_bed
