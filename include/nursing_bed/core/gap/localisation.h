// Where in time the model and a run part: a short-horizon residual that restarts the model
// from the measured state at the start of every window, so an early error does not smear over
// the rest of the run, and events (onset and end in seconds, per signal) where the windows'
// residual stands out from what the model leaves at the same point of the other cycles.
// ROS-free (doc/gap_diagnosis.md#where-it-lies-in-time).
#pragma once

#include <string>
#include <vector>

#include "nursing_bed/core/gap/replay.h"
#include "nursing_bed/core/gap/run_data.h"

namespace nursing_bed {

struct LocalisationOptions {
  double window_s = 0.25;  ///< length of the re-anchored windows [s]
  /// A window is part of an event when its RMS residual is above this many times the floor at
  /// its point of the cycle (the median over the run's cycles) ...
  double floor_ratio = 3.0;
  /// ... and above this many noise floors.
  double min_rms = 3.0;
  /// Events closer than this are one event [s].
  double merge_gap_s = 1.0;
  /// Fewer cycles than this: the floor is the noise (a run that is not cyclic).
  int min_cycles = 3;
  std::string validate() const;  ///< empty when usable, else what is wrong
};

/// One re-anchored window: the model restarted at rest at the measured state at t_start_s
/// (replayRun's start) and replayed to t_end_s; RMS of its residual in noise floors, per signal
/// (NaN: no such reading, or the replay failed).
struct AnchoredWindow {
  double t_start_s = 0.0, t_end_s = 0.0;
  int cycle = 0;  ///< index of the cycle the window starts in
  int slot = 0;   ///< index of the window within its cycle
  double rms_p = 0.0, rms_h = 0.0;
};

/// Where a signal's re-anchored residual stands out: from onset_s to end_s.
struct GapEvent {
  std::string run;
  std::string signal;  ///< "pressure" or "height"
  double onset_s = 0.0, end_s = 0.0;
  double peak_rms = 0.0;   ///< largest window RMS inside it [noise floors]
  double floor_rms = 0.0;  ///< the floor at that window's point of the cycle [noise floors]
};

/// Cycle starts of a run: the rising edges of its pressure setpoint (p_setpoint_gauge_pa: a
/// step up by more than a quarter of the setpoint's range from below its middle); the first
/// sample alone for a run without one.
std::vector<double> cycleStarts(const RunData& run);

/// The run cut into windows of options.window_s that start at every cycle start (the last one of
/// a cycle is cut short at the next), each replayed from rest at its measured state through
/// `params` and `effects`. RMS in noise floors: `noise_p_pa`, `noise_h_m` (the sensors' noise),
/// or the median of the windows' own noise estimates where that is smaller (a fault that rings
/// over part of the run inflates a whole-run estimate).
std::vector<AnchoredWindow> anchoredWindows(const RunData& run, const CellParams& params,
                                            const std::vector<CellEffectPtr>& effects, double noise_p_pa,
                                            double noise_h_m, const LocalisationOptions& options);

/// Events of one run from its windows (anchoredWindows), per signal, earliest first.
std::vector<GapEvent> eventsFromWindows(const std::string& run_name, const std::vector<AnchoredWindow>& windows,
                                        const LocalisationOptions& options);

/// Both steps for one run. Throws std::invalid_argument for options that fail validate().
std::vector<GapEvent> localiseInTime(const RunData& run, const CellParams& params,
                                     const std::vector<CellEffectPtr>& effects, double noise_p_pa, double noise_h_m,
                                     const LocalisationOptions& options = {});

}  // namespace nursing_bed
