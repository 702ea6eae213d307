// Replaying recorded runs through the cell model, and where model and data part (the first of
// the gap diagnosis' three answers; doc/formats/gap_report.md). ROS-free.
#pragma once

#include <string>
#include <vector>

#include "nursing_bed/core/gap/run_data.h"
#include "nursing_bed/core/physics/cell_model.h"

namespace nursing_bed {

/// Whether a run is driven through the model's own valves: no flow reading at all, but valve_cmd
/// and p_supply_gauge_pa (doc/formats/run_data.md, "Three kinds of run"). replayRun() then opens the
/// model's inlet (from the supply) by valve_cmd > 0 and its vent by -valve_cmd.
bool runIsValveDriven(const RunData& run);

/// Phase of a run at one sample (doc/formats/gap_report.md): bag unfolding, bag pressurising, inlet closed,
/// venting; `landed` marks vent samples after the plate has come down on the bed, where a
/// replay is ill-conditioned (a few mL of gas left) and which the diagnosis leaves out.
enum class RunPhase { kDeploy, kPressurize, kHold, kVent, kLanded };
const char* phaseName(RunPhase phase);

/// Per-sample phases from the measured signals (valve_cmd in place of the inflow for a
/// valve-driven run): inflating while the inflow exceeds 2 % of its
/// peak (deploy while the pressure is below a quarter of the inflation's peak pressure, then
/// pressurize), venting from the first clearly negative inflow, hold in between; landed once
/// the measured height is below 3 mm during the vent, or, for a metered run without height
/// readings, once the vent's flow and pressure stay at zero within the noise for 0.5 s.
std::vector<RunPhase> classifyPhases(const RunData& run);

/// A run replayed through a model: the simulated readings at the measured times.
struct Replay {
  std::vector<double> p_gauge_pa;  ///< simulated pressure reading (sensor effects applied) [Pa]
  std::vector<double> h_m;         ///< simulated height reading [m]
  std::vector<RunPhase> phases;
  bool ok = true;     ///< false: the model failed (the message says why)
  long substeps = 0;  ///< integration sub-steps spent
  std::string message;
};

/// The height a run starts from: the mean of its readings over the first kInitialRestS (one
/// noisy reading would put the sensor's noise into the replay's gas for the whole run: at
/// 5 cm, 0.3 mm of height is 0.6 % of the gas), and how many readings that mean has.
constexpr double kInitialRestS = 0.2;
/// Below this height the plate rests on the bed (a run starting there starts flat).
constexpr double kLandedHeightM = 0.003;
struct InitialHeight {
  double h_m = 0.0;
  int samples = 0;
};
InitialHeight initialHeight(const RunData& run);

/// Where an interval-mean flow's gas goes within its interval. kSpread: evenly (the replay's
/// model of the data). The pulse shapes are the extremes of what the mean allows, for the noise
/// model: the bed's valves are on/off, so an interval whose mean opening is d (valve_cmd; 0.5
/// without a valve record) had its valve open d of the time, here at the interval's start or
/// end, at the flow (or the vent's full opening) that gives the same gas.
enum class IntervalShape { kSpread, kPulseAtStart, kPulseAtEnd };

/// Whether `effects`' height gain, offset or drift move the start replayRun() takes from `run`'s
/// height readings (a start read flat and flat in truth does not move): a replay without them,
/// its readings transformed, then is not the replay with them.
bool distortionsMoveTheStart(const RunData& run, const std::vector<CellEffectPtr>& effects);

/// Which readings give a replay its start. kReadings: the height's, else the pressure's
/// (replayRun()). kNotHeight: the pressure's alone, for a height sensor that reads early (a
/// negative height shift, distortions.h): its first readings show the plate after the start.
enum class ReplayStart { kReadings, kNotHeight };

/**
 * Replays `run` through a cell with `params` and `effects`: the measured inflow is the input
 * (the paper's way), the load follows the run's load (column or constant), and the cell starts
 * flat at ambient, or at rest at initialHeight() if that is above 3 mm; a run without height
 * readings starts at rest at its first measured pressure (mean over kInitialRestS while steady)
 * when that is above 150 Pa (a ventilated lung at PEEP; a flat cell reads noise around 0); at
 * the first measured gas temperature if the run has one. Samples after the plate has landed in the
 * vent (kLanded) are not simulated: NaN. `max_substeps` bounds the integration's cost (0: 50
 * sub-steps per default step on average): a replay that needs more accepted sub-steps fails
 * ("too stiff"), as a fit may wander into parameters that make the model needlessly stiff.
 * With a height sensor read early among `effects`, the start is ReplayStart::kNotHeight's; with
 * a height gain, offset or drift among them, the start is taken from the height readings those
 * undo (undoHeightReadingDistortions()): a flat start read 10 mm up is still flat.
 */
Replay replayRun(const RunData& run, const CellParams& params, const std::vector<CellEffectPtr>& effects,
                 long max_substeps = 0, IntervalShape shape = IntervalShape::kSpread);
/// The same with the start given (the replay without effects that output-side distortions
/// transform, fit_model.cpp).
Replay replayRun(const RunData& run, const CellParams& params, const std::vector<CellEffectPtr>& effects,
                 long max_substeps, IntervalShape shape, ReplayStart start);

/// Noise of a measured signal: robust (median absolute deviation) estimate from second
/// differences, sd = 1.4826 MAD / sqrt(6); exact for white noise on a smooth signal. At least
/// the rounding's sd, step / sqrt(12), of a signal read on a lattice (quantisationStep()): a
/// channel whose steps are coarse against its noise reads constant for long stretches, and its
/// second differences' MAD falls to 0.
double estimateNoise(const std::vector<double>& signal);

/// The step of a signal read on a lattice (an ADC's or a log's resolution): the smallest change
/// between samples, where at least 90 % of the changes are whole multiples of it (within 1 %
/// of a step); 0 where the readings are not on one or change fewer than 10 times.
double quantisationStep(const std::vector<double>& signal);

/// The flow meter's noise around each sample of `flow` (the run's inflow as measured): the
/// estimate of estimateNoise() (its rounding floor included) over the samples i-w .. i+w (a meter's noise grows with its
/// reading), from the samples where the valve held still (valve_cmd equal at i-1, i, i+1, when
/// the run has it). A valve that the controller opens for a few ms at a time moves gas in
/// pulses, and those are flow, not the meter's noise (taken as noise they would pose as one
/// hundreds of times the meter's). Where fewer than 5 such samples are near, the estimate
/// over all of the run's; a run whose valve never held still, every sample.
std::vector<double> meterNoise(const RunData& run, const std::vector<double>& flow, std::size_t w);

/// Whether the run vents through a valve of its own that the inlet's meter does not see (a
/// bed's cell): valve_cmd < 0 (venting) while the metered flow stays near zero (above -1 % of the
/// peak inflow per unit of mean vent opening, or within 3 standard errors of the meter's noise),
/// judged on runs of venting intervals, or on single pulses where the controller vents only in
/// those. The replay then opens the model's vent valve by -valve_cmd.
bool ventsThroughUnmeteredValve(const RunData& run);

/**
 * Where the inlet is closed, a flow meter reads noise around zero (and its offset, if it has
 * one). Replaying that reading integrates the noise into a random walk of the gas mass that no
 * model can follow. Closed stretches come from the valve_cmd column (== 0) where it is
 * recorded, else from the hold phase without the ends whose flow is not yet zero within the
 * noise (half-second chunks: the inflow's tail, the vent's start). A stretch whose mean flow is
 * within 3 standard errors of zero gets exactly 0; one with a clear offset is left as
 * measured, so a meter offset still shows. Returns the number of samples set to 0.
 */
int zeroClosedInletFlow(RunData* run);

/// Residual statistics of one run against its replay (samples not landed).
struct RunResidual {
  double range_p_pa = 0.0, range_h_m = 0.0;  ///< measured ranges (the nrmse denominators)
  double nrmse_p = 0.0, nrmse_h = 0.0;       ///< RMS(measured - simulated) / range
  /// Mean over the two signals; pressure alone for runs without a height sensor.
  double nrmse() const { return samples_h > 0 ? 0.5 * (nrmse_p + nrmse_h) : nrmse_p; }
  int samples = 0;    ///< with a pressure reading
  int samples_h = 0;  ///< with a height reading too
};
RunResidual runResidual(const RunData& run, const Replay& replay);
/// The same over several runs pooled (the report's nrmse "on the runs named"): RMS over all
/// their samples, divided by the range of the measured signal over all of them.
RunResidual pooledResidual(const std::vector<const RunData*>& runs, const std::vector<const Replay*>& replays);

/// One line of "where it lies": a share of the total squared normalised residual.
struct GapShare {
  std::string signal;  ///< "pressure" or "height"
  std::string phase;   ///< deploy, pressurize, hold, vent
  double load_n = 0.0;
  double share = 0.0;
  double t_start_s = 0.0, t_end_s = 0.0;  ///< where that phase lies in those runs
};
/// Splits the squared residual, normalised per signal by the measured range over all runs, by
/// signal, phase and load; largest first.
std::vector<GapShare> localizeGap(const std::vector<RunData>& runs, const std::vector<Replay>& replays);

}  // namespace nursing_bed
