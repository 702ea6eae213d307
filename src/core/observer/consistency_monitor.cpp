#include "nursing_bed/core/observer/consistency_monitor.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/io/errors.h"

namespace nursing_bed {
Status ConsistencyMonitorParams::validate() const {
  ErrorList errors;
  auto nonNegative = [&](const char* key, double v) {
    errors.addIf(!(v >= 0.0 && std::isfinite(v)), key, " must be finite and >= 0, got ", v);
  };
  auto positive = [&](const char* key, double v) {
    errors.addIf(!(v > 0.0 && std::isfinite(v)), key, " must be finite and > 0, got ", v);
  };
  nonNegative("frozen_s", frozen_s);
  nonNegative("settle_s", settle_s);
  positive("reference_time_s", reference_time_s);
  nonNegative("load_rate_pa_s", load_rate_pa_s);
  nonNegative("hold_correction_pa", hold_correction_pa);
  nonNegative("drift_sds", drift_sds);
  nonNegative("min_drift_pa", min_drift_pa);
  positive("cusum_threshold_pa_s", cusum_threshold_pa_s);
  positive("surprise_m", surprise_m);
  positive("jump_pa", jump_pa);
  nonNegative("response_min_pa", response_min_pa);
  positive("response_sds", response_sds);
  nonNegative("response_silent_sum_pa", response_silent_sum_pa);
  positive("response_single_pa", response_single_pa);
  nonNegative("response_steady_s", response_steady_s);
  positive("response_steady_sds", response_steady_sds);
  positive("response_steady_single_pa", response_steady_single_pa);
  errors.addIf(response_silent_pulses < 1, "response_silent_pulses must be >= 1, got ", response_silent_pulses);
  nonNegative("response_window_s", response_window_s);
  nonNegative("response_min_period_s", response_min_period_s);
  nonNegative("max_load_n", max_load_n);
  nonNegative("landed_height_m", landed_height_m);
  positive("landed_time_s", landed_time_s);
  nonNegative("progress_inlet_m", progress_inlet_m);
  nonNegative("progress_vent_m", progress_vent_m);
  errors.addIf(!(progress_rel > 0.0 && progress_rel < 1.0), "progress_rel must lie in (0, 1), got ", progress_rel);
  positive("progress_min_pa", progress_min_pa);
  positive("progress_window_s", progress_window_s);
  return errors.status();
}

namespace {
const ConsistencyMonitorParams& validated(const ConsistencyMonitorParams& p) {
  const Status valid = p.validate();
  if (!valid.ok()) throw std::invalid_argument("consistency monitor parameters: " + valid.message());
  return p;
}
}  // namespace

ConsistencyMonitor::ConsistencyMonitor(const ConsistencyMonitorParams& params) : params_(validated(params)) {}

bool ConsistencyMonitor::update(const ConsistencySample& sample, double dt_s) {
  if (!std::isfinite(sample.gauge_pressure_pa) || !(dt_s > 0.0)) {
    interrupt();
    return false;
  }
  if (inconsistent()) return false;
  std::ostringstream why;
  // Settled before this reading (the valves acting over its period included): a plate still
  // ringing after a fill from flat swings by kilopascals between two readings.
  const bool settled = sample.valves_shut && shut_for_s_ >= params_.settle_s;
  if (const std::string sensor = sensor_.update(sample.gauge_pressure_pa, settled, sample.noise_sd_pa, dt_s, params_);
      !sensor.empty()) {
    why << sensor;
  } else if (std::fabs(sample.correction_m) > params_.surprise_m) {
    why << "the plate's weight bound corrected the height by " << 1e3 * sample.correction_m << " mm (limit "
        << 1e3 * params_.surprise_m << " mm)";
  } else if (params_.max_load_n > 0.0 && sample.load_n > params_.max_load_n) {
    why << "the observer's load " << sample.load_n << " N exceeds any a cell carries (" << params_.max_load_n
        << " N): the pressure is more than its counted gas can hold";
  } else if (landed(sample, dt_s)) {
    why << "the pressure reads a flat cell (mean " << landed_mean_pa_ << " Pa for " << params_.landed_time_s
        << " s, flat below " << sample.flat_pressure_pa << ") while the gas counted holds the plate at "
        << 1e3 * sample.height_m << " mm: gas left uncounted";
  } else if (const std::string silent = response_.update(sample, dt_s, params_); !silent.empty()) {
    why << silent;
  } else {
    progress_.update(sample, dt_s, params_);  // a doubt, not an inconsistency
    if (innovation(sample, dt_s))
      why << "pressure " << sample.gauge_pressure_pa << " Pa departs from the hold's " << reference_pa_
          << " Pa with both valves shut (CUSUM " << cusum() << " Pa s)";
  }
  reason_ = why.str();
  return inconsistent();
}

double ValveProgressCheck::takeDoubtKg() {
  const double kg = doubt_kg_;
  doubt_kg_ = 0.0;
  return kg;
}

std::string SensorSignatureCheck::update(double reading_pa, bool settled, double noise_sd_pa, double dt_s,
                                         const ConsistencyMonitorParams& params) {
  // A load's step moves a settled plate along its gas's isentrope over a quarter of its
  // gas-spring period and rings it after, so the reading after a body's jump has moved on
  // again; a sensor's offset (or a terminal serving another image) stays where it jumped. The
  // controller's answer to the jump acts only after the valves' dead time.
  constexpr double kHoldFraction = 0.25;  // of the jump: "stayed"
  // The reason is formatted only when there is one: this runs every reading of every cell.
  bool held = false;
  if (jump_pending_) {
    const double tolerance = std::max(3.0 * noise_sd_pa, kHoldFraction * std::fabs(jump_to_pa_ - jump_from_pa_));
    held = std::fabs(reading_pa - jump_to_pa_) <= tolerance;
    jump_pending_ = false;
  }
  if (!held && settled && have_last_ && std::fabs(reading_pa - last_pa_) > params.jump_pa) {
    jump_pending_ = true;
    jump_from_pa_ = last_pa_;
    jump_to_pa_ = reading_pa;
  }
  same_for_s_ = have_last_ && reading_pa == last_pa_ ? same_for_s_ + dt_s : 0.0;
  last_pa_ = reading_pa;
  have_last_ = true;
  const bool frozen = params.frozen_s > 0.0 && same_for_s_ >= params.frozen_s;
  if (!held && !frozen) return "";
  std::ostringstream why;
  if (held)
    why << "pressure jumped from " << jump_from_pa_ << " to " << jump_to_pa_
        << " Pa in one reading under a settled plate and stayed there";
  else why << "pressure reading frozen at " << reading_pa << " Pa for " << same_for_s_ << " s";
  return why.str();
}

void SensorSignatureCheck::restart() {
  have_last_ = false;
  jump_pending_ = false;
  same_for_s_ = 0.0;
}

bool ConsistencyMonitor::innovation(const ConsistencySample& sample, double dt_s) {
  // Page's CUSUM: g+ = max(0, g+ + (nu - k) dt), g- likewise for -nu, with nu the reading less
  // the hold's running mean and k the drift the noise is allowed. Nothing counts until the
  // plate has settled after the last valve edge.
  // A hold's small corrections (a fraction of a reading sd at fixed volume) do not end it: a
  // controller nudging its estimate would otherwise keep the test from ever running.
  const bool holding = sample.valves_shut || (sample.counted_step_pa != 0.0 &&
                                              std::fabs(sample.counted_step_pa) < params_.hold_correction_pa);
  shut_for_s_ = holding ? shut_for_s_ + dt_s : 0.0;
  if (shut_for_s_ < params_.settle_s) {
    have_reference_ = false;
    up_pa_s_ = down_pa_s_ = 0.0;
    return false;
  }
  const double p = sample.gauge_pressure_pa;
  if (!have_reference_) {
    reference_pa_ = p;
    have_reference_ = true;
    return false;
  }
  const double nu = p - reference_pa_;
  const double k = std::max(params_.min_drift_pa, params_.drift_sds * sample.noise_sd_pa);
  up_pa_s_ = std::max(0.0, up_pa_s_ + (nu - k) * dt_s);
  down_pa_s_ = std::max(0.0, down_pa_s_ + (-nu - k) * dt_s);
  if (cusum() >= params_.cusum_threshold_pa_s) return true;
  reference_pa_ += (p - reference_pa_) * std::min(1.0, dt_s / params_.reference_time_s);
  // A load change: the part of the departure beyond the noise, followed at the rate a body
  // can load the cell. A step of S Pa then adds (S - k)^2 / (2 load_rate) to the CUSUM.
  const double beyond = std::fabs(nu) - k;
  if (beyond > 0.0) reference_pa_ += std::copysign(std::min(beyond, params_.load_rate_pa_s * dt_s), nu);
  return false;
}

bool ConsistencyMonitor::landed(const ConsistencySample& sample, double dt_s) {
  // The observer's own flat test (its mean below flat_pressure_pa) under an estimate that has
  // the plate lifted, for landed_time_s: the readings' mean over a quarter of it (one noisy
  // reading is not a flat cell). The plate alone lifted reads at least twice flat_pressure_pa.
  const double w = std::min(1.0, dt_s / (0.25 * params_.landed_time_s));
  landed_mean_pa_ = landed_for_s_ < 0.0 ? sample.gauge_pressure_pa
                                        : landed_mean_pa_ + (sample.gauge_pressure_pa - landed_mean_pa_) * w;
  const bool lifted = params_.landed_height_m > 0.0 && sample.height_m > params_.landed_height_m;
  const bool flat = sample.flat_pressure_pa > 0.0 && std::fabs(landed_mean_pa_) < sample.flat_pressure_pa;
  landed_for_s_ = lifted && flat ? std::max(0.0, landed_for_s_) + dt_s : 0.0;
  return landed_for_s_ >= params_.landed_time_s;
}

void ConsistencyMonitor::interrupt() {
  response_.restart();
  progress_.restart();
  sensor_.restart();
  shut_for_s_ = 0.0;
  have_reference_ = false;
  up_pa_s_ = down_pa_s_ = 0.0;
  landed_for_s_ = -1.0;
}

void ConsistencyMonitor::clear() {
  reason_.clear();
  interrupt();
}

void SteadyReadings::add(double reading_pa, double dt_s) {
  p_[next_] = reading_pa;
  dt_[next_] = dt_s;
  next_ = (next_ + 1) % kReadings;
  count_ = std::min(kReadings, count_ + 1);
}

bool SteadyReadings::within(double span_s, double range_pa) const {
  double lo = std::numeric_limits<double>::infinity(), hi = -lo, seen_s = 0.0;
  for (int i = 1; i <= count_ && seen_s < span_s; ++i) {
    const int k = (next_ + kReadings - i) % kReadings;
    lo = std::min(lo, p_[k]);
    hi = std::max(hi, p_[k]);
    seen_s += dt_[k];
  }
  return seen_s >= span_s && hi - lo <= range_pa;
}

void SteadyReadings::clear() {
  count_ = 0;
  next_ = 0;
}

void QuarterSwingSum::start(double plate_period_s) {
  quarter_s_ = 0.25 * plate_period_s;
  count_ = 0;
  next_ = 0;
  largest_pa_ = 0.0;
}

void QuarterSwingSum::add(double step_pa, double dt_s) {
  step_pa_[next_] = step_pa;
  dt_s_[next_] = dt_s;
  next_ = (next_ + 1) % kSteps;
  count_ = std::min(kSteps, count_ + 1);
  // The steps of the last quarter swing, the newest always (a step spans its own period).
  double sum_pa = 0.0, span_s = 0.0;
  for (int i = 1; i <= count_; ++i) {
    const int k = (next_ + kSteps - i) % kSteps;
    if (i > 1 && span_s + dt_s_[k] > quarter_s_) break;
    sum_pa += step_pa_[k];
    span_s += dt_s_[k];
  }
  largest_pa_ = std::max(largest_pa_, std::fabs(sum_pa));
}

std::string ValveResponseCheck::update(const ConsistencySample& sample, double dt_s,
                                       const ConsistencyMonitorParams& params) {
  const double p = sample.gauge_pressure_pa;
  const int direction = sample.counted_step_pa > 0.0 ? 1 : (sample.counted_step_pa < 0.0 ? -1 : 0);
  // Whether the readings before this one were steady, asked only where a pulse may start (not
  // on each period of one under way).
  const bool steady_before = params.response_steady_s > 0.0 && direction != 0 && direction != direction_ &&
                             steady_.within(params.response_steady_s, params.response_steady_sds * sample.noise_sd_pa);
  steady_.add(p, dt_s);
  for (int i = kRecent - 1; i > 0; --i) recent_[i] = recent_[i - 1];
  recent_[0] = p;
  double recent_pa = 0.0;
  for (const double r : recent_) recent_pa += r / kRecent;
  std::string why;
  if (direction_ != 0) {
    best_pa_ = std::max(best_pa_, direction_ * (recent_pa - baseline_pa_));
    if (direction == direction_) {
      counted_pa_ += sample.counted_step_pa;
      quarter_.add(sample.counted_step_pa, dt_s);
      after_s_ = 0.0;
      open_s_ += dt_s;
      return judgeOpenInlet(sample.noise_sd_pa, params);
    }
    after_s_ += dt_s;
    quarter_.add(0.0, dt_s);  // a gap in the pulse: its steps before it count as older
    // Judged once the window after the counted flow has passed, or when the other valve opens.
    if (direction == 0 && after_s_ < params.response_window_s) return why;
    why = judge(sample.noise_sd_pa, params);
    direction_ = 0;
    pre_count_ = 0;
  }
  if (direction != 0 && pre_count_ >= kPre) {
    baseline_pa_ = 0.0;
    for (const double r : pre_) baseline_pa_ += r / kPre;
    direction_ = direction;
    slow_enough_ = sample.plate_period_s >= params.response_min_period_s;
    steady_start_ = steady_before;
    counted_pa_ = sample.counted_step_pa;
    quarter_.start(sample.plate_period_s);
    quarter_.add(sample.counted_step_pa, dt_s);
    best_pa_ = direction * (recent_pa - baseline_pa_);
    after_s_ = 0.0;
    open_s_ = 0.0;
  } else if (direction == 0) {
    pre_[pre_next_] = p;
    pre_next_ = (pre_next_ + 1) % kPre;
    pre_count_ = std::min(kPre, pre_count_ + 1);
  }
  return why;
}

bool ValveResponseCheck::judgeable(double needed_pa, const ConsistencyMonitorParams& params) const {
  // A vent can take the pressure down to ambient at most: a plate that rests at a few
  // reading sds (a light one) has no room to show its vent working.
  const bool room = (direction_ > 0 || baseline_pa_ >= 2.0 * needed_pa) && slow_enough_;
  // A valve that does not open leaves the readings where they were; readings that stayed
  // against the pulse by more than that all along (a load shifting meanwhile) do not judge it.
  const bool still = best_pa_ > -needed_pa;
  return params.response_min_pa > 0.0 && std::fabs(counted_pa_) >= params.response_min_pa && room && still;
}

std::string ValveResponseCheck::judge(double noise_sd_pa, const ConsistencyMonitorParams& params) {
  const double needed_pa = params.response_sds * noise_sd_pa;
  const double counted_pa = std::fabs(counted_pa_);
  if (!judgeable(needed_pa, params)) return "";
  const int v = direction_ > 0 ? 0 : 1;
  if (best_pa_ >= needed_pa) {
    silent_[v] = SilentRun{};
    return "";
  }
  // A run counts only vent pulses with room for their whole step: near ambient a plate under a
  // body's part can settle with it and hold the pressure while its vent works.
  const bool alone = aloneShowsStuck(counted_pa, params);
  if (direction_ < 0 && baseline_pa_ < 2.0 * counted_pa && !alone) return "";
  silent_[v].worth_pa += counted_pa;
  ++silent_[v].pulses;
  const bool run = params.response_silent_sum_pa > 0.0 && silent_[v].pulses >= params.response_silent_pulses &&
                   silent_[v].worth_pa >= params.response_silent_sum_pa;
  if (!run && !alone) return "";
  return stuckShut(silent_[v].worth_pa, silent_[v].pulses, needed_pa);
}

std::string ValveResponseCheck::judgeOpenInlet(double noise_sd_pa, const ConsistencyMonitorParams& params) const {
  // An inlet held open (a move's full flow) would be judged at the move's end, seconds after it
  // was found silent: it is judged once it is worth a single silent pulse and the response
  // window has passed. A working inlet has moved the pressure by then (its gas lifts the plate
  // and the load on it). Vents keep the end's judgement: a body's part can settle with the plate.
  const double needed_pa = params.response_sds * noise_sd_pa;
  if (direction_ <= 0 || open_s_ < params.response_window_s || !aloneShowsStuck(counted_pa_, params) ||
      !judgeable(needed_pa, params) || best_pa_ >= needed_pa) {
    return "";
  }
  return stuckShut(counted_pa_, 1, needed_pa) + " (still counted open)";
}

std::string ValveResponseCheck::stuckShut(double worth_pa, int pulses, double needed_pa) const {
  std::ostringstream why;
  why << "the " << (direction_ > 0 ? "inlet" : "vent") << " was counted to pass gas worth " << worth_pa
      << " Pa at fixed volume over " << pulses << " pulse(s), none moving the pressure " << needed_pa << " Pa its way";
  if (steady_start_) why << " from steady readings (" << quarter_.largestPa() << " Pa of it within a quarter swing)";
  why << ": a valve that does not open";
  return why.str();
}

bool ValveResponseCheck::aloneShowsStuck(double counted_pa, const ConsistencyMonitorParams& params) const {
  if (counted_pa >= params.response_single_pa) return true;
  const double quick_pa = quarter_.largestPa();
  return steady_start_ && quick_pa >= params.response_steady_single_pa &&
         (direction_ > 0 || baseline_pa_ >= 2.0 * quick_pa);
}

void ValveResponseCheck::restart() {
  silent_.fill(SilentRun{});
  direction_ = 0;
  pre_count_ = 0;
  pre_next_ = 0;
  recent_.fill(0.0);
  steady_.clear();
  steady_start_ = false;
}

std::string ValveProgressCheck::update(const ConsistencySample& sample, double dt_s,
                                       const ConsistencyMonitorParams& params) {
  // The readings' mean over about half the settling time (kSettleS), so it has caught up with
  // the pressure by the judgement: 10 readings take a 10 Pa noise to about 3 Pa, against the
  // tens a working valve moves the pressure by over its summed gas.
  constexpr double kMeanTimeS = 0.5 * kSettleS;
  const double p = sample.gauge_pressure_pa;
  mean_pa_ = have_mean_ ? mean_pa_ + (p - mean_pa_) * std::min(1.0, dt_s / kMeanTimeS) : p;
  have_mean_ = true;
  // Either valve moves the pressure: the other's sum ends when it opens. A sum that reached its
  // limit is judged then, on the furthest the pressure went meanwhile: a move up that turns
  // into a ramp down (or back) never rests between the two, and dropped unjudged a valve stuck
  // shut went unseen while the estimate climbed away from its plate.
  std::string why;
  if (sample.vent_opening > 0.0) why = endWindow(&inlet_, +1, params.progress_inlet_m, params);
  if (sample.inlet_opening > 0.0 && why.empty()) why = endWindow(&vent_, -1, params.progress_vent_m, params);
  if (!why.empty()) return why;
  why = step(&inlet_, +1, sample.inlet_opening, sample, params.progress_inlet_m, dt_s, params);
  if (why.empty()) why = step(&vent_, -1, sample.vent_opening, sample, params.progress_vent_m, dt_s, params);
  return why;
}

std::string ValveProgressCheck::step(Window* w, int direction, double opening, const ConsistencySample& sample,
                                     double limit_m, double dt_s, const ConsistencyMonitorParams& params) {
  if (limit_m <= 0.0) return "";
  if (opening > 0.0 && !w->active) *w = Window{true, 0.0, 0.0, 0.0, mean_pa_, 0.0, 0.0, 0.0};
  if (!w->active) return "";
  w->open_s += opening * dt_s;
  if (opening > 0.0) {
    w->height_m += sample.counted_height_m;
    w->gas_kg += sample.counted_gas_kg;
  }
  w->span_s += dt_s;
  // The furthest its way: a fast move's plate still swings when the valves rest, and a
  // pulse moves the pressure at fixed volume before the plate takes it up.
  w->best_pa = std::max(w->best_pa, direction * (mean_pa_ - w->start_pa));
  if (w->span_s > params.progress_window_s) {
    w->active = false;  // too slow to tell from a body's load changes
    return "";
  }
  // Judged a few of the plate's swings (tens of ms each) after its gas reached the limit, the
  // valves resting or not (a slow ramp's pulses come every tenth of a second): the mean has
  // caught up by then, and the furthest it went counts.
  if (w->height_m < limit_m) return "";
  w->reached_s += dt_s;
  if (w->reached_s < kSettleS) return "";
  return judge(w, direction, params);
}

std::string ValveProgressCheck::endWindow(Window* w, int direction, double limit_m,
                                          const ConsistencyMonitorParams& params) {
  if (!w->active) return "";
  if (limit_m > 0.0 && w->height_m >= limit_m && w->reached_s >= kSettleS) return judge(w, direction, params);
  w->active = false;
  return "";
}

std::string ValveProgressCheck::judge(Window* w, int direction, const ConsistencyMonitorParams& params) {
  w->active = false;
  // A vent shows nothing at ambient; a light plate's pressure hardly moves along the structure.
  const double needed_pa = params.progress_rel * w->start_pa;
  const double moved_pa = w->best_pa;
  if (needed_pa < params.progress_min_pa || moved_pa >= needed_pa) return "";
  doubt_kg_ += w->gas_kg;
  ++failures_;
  std::ostringstream why;
  why << "failure to reach target: the " << (direction > 0 ? "inlet" : "vent") << " was counted open " << w->open_s
      << " s, worth " << 1e3 * w->height_m << " mm, over " << w->span_s << " s but the pressure moved " << moved_pa
      << " Pa its way from " << w->start_pa << " Pa (less than " << needed_pa << " Pa): a valve that does not open";
  last_failure_ = why.str();
  return last_failure_;
}

void ValveProgressCheck::restart() {
  inlet_ = Window{};
  vent_ = Window{};
  have_mean_ = false;
}

double ConsistencyMonitor::cusum() const { return std::max(up_pa_s_, down_pa_s_); }

}  // namespace nursing_bed
