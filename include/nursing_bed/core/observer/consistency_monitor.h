// A cell's consistency monitor (ROS-free): tests over time whether the readings agree with what
// the observer believes, and says when they persistently do not, whatever the cause (a device
// that restarted empty, a stuck valve, a leak the model lacks, a frozen or drifting sensor).
#pragma once

#include <string>

#include "nursing_bed/core/io/status.h"

namespace nursing_bed {

struct ConsistencyMonitorParams {
  /// The same raw reading this long is a frozen sensor (a live sensor's noise and ADC step
  /// change it every few readings); 0: off [s].
  double frozen_s = 1.0;
  /// Both valves shut this long before the pressure is held to its hold's mean (a plate rings
  /// on its gas spring after a valve edge) [s].
  double settle_s = 0.5;
  /// Time constant of the hold's reference pressure, the innovation's prediction [s].
  double reference_time_s = 2.0;
  /// Innovation within this many reading sds (and at least min_drift_pa) is noise [-].
  double drift_sds = 6.0;
  double min_drift_pa = 150.0;  ///< least innovation the CUSUM counts [Pa]
  /// The CUSUM of the innovation beyond the drift that is a persistent inconsistency [Pa s].
  double cusum_threshold_pa_s = 60.0;
  /// A settled plate's pressure cannot move this much between two readings: the gas spring
  /// and the plate's inertia spread even a patient dropping onto it over several readings,
  /// while a sensor that jumps (an offset, a terminal serving another image) does it at once [Pa].
  double jump_pa = 1200.0;
  /// A weight bound that moves the estimate more than this showed it wrong [m].
  double surprise_m = 0.006;

  /// Success when valid, else an error with every problem found, separated by "; ".
  Status validate() const;
};

/// What one reading told the monitor.
struct ConsistencySample {
  double gauge_pressure_pa = 0.0;  ///< the raw reading [Pa]
  double noise_sd_pa = 10.0;       ///< the readings' sd as the observer has it [Pa]
  bool valves_shut = false;        ///< both valves shut over the period (the inputs acting)
  /// How far a correction of the observer's that does not prove the gas (a weight bound)
  /// moved the height in this period [m]; 0 without one.
  double correction_m = 0.0;
};

/**
 * Four tests:
 *  - frozen: the raw reading unchanged for frozen_s;
 *  - jump: a settled plate's reading moves more than jump_pa from one reading to the next (a
 *    controller reacts to the first reading of a jump at once, so a test over time would see
 *    only its response);
 *  - innovation: while both valves are shut and the plate settled, the pressure predicted is
 *    the hold's running mean (nothing moves gas, so a plate held by a steady load keeps its
 *    pressure); a two-sided CUSUM of the reading's departure from it beyond the noise
 *    (Page's test, in Pa s) crosses cusum_threshold_pa_s on a persistent step (an offset
 *    sensor, a sudden leak or valve flow under a settled plate, a terminal that restarted);
 *  - surprise: a correction of the observer's that does not prove the gas (a weight bound)
 *    larger than surprise_m: the estimate was that far wrong.
 * Once inconsistent it stays so until clear() (the cell's gas re-verified).
 */
class ConsistencyMonitor {
 public:
  /// Throws std::invalid_argument naming what is wrong in `params`.
  explicit ConsistencyMonitor(const ConsistencyMonitorParams& params = {});
  const ConsistencyMonitorParams& params() const { return params_; }

  /// One period of `dt_s`: true when this reading made the cell inconsistent.
  bool update(const ConsistencySample& sample, double dt_s);
  /// A period without readings (a lost link): the tests start again.
  void interrupt();
  /// The gas was re-verified: consistent again, the tests from the start.
  void clear();

  bool inconsistent() const { return !reason_.empty(); }
  /// Why the cell is inconsistent ("" when it is not).
  const std::string& reason() const { return reason_; }
  /// The larger of the two CUSUMs now [Pa s].
  double cusum() const;

 private:
  bool frozen(double gauge_pressure_pa, double dt_s);
  /// The jump test on this reading against the last (before frozen() takes it).
  bool jumped(const ConsistencySample& sample) const;
  bool innovation(const ConsistencySample& sample, double dt_s);

  ConsistencyMonitorParams params_;
  std::string reason_;
  double last_reading_pa_ = 0.0;
  bool have_reading_ = false;
  double same_for_s_ = 0.0;    ///< the raw reading unchanged this long [s]
  double shut_for_s_ = 0.0;    ///< both valves shut this long [s]
  double reference_pa_ = 0.0;  ///< the hold's running mean (valid once the plate settled)
  bool have_reference_ = false;
  double up_pa_s_ = 0.0, down_pa_s_ = 0.0;  ///< the two CUSUMs [Pa s]
};

}  // namespace nursing_bed
