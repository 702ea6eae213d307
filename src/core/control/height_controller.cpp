#include "nursing_bed/core/control/height_controller.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "nursing_bed/core/physics/orifice.h"
#include "nursing_bed/core/physics/units.h"

namespace nursing_bed {

std::string HeightControllerParams::validate() const {
  std::ostringstream err;
  auto check = [&err](bool ok, const char* what) {
    if (!ok) err << what << "; ";
  };
  check(std::isfinite(min_height_m) && min_height_m >= 0.0, "min_height_m must be >= 0");
  check(std::isfinite(max_height_m) && max_height_m > min_height_m, "max_height_m must exceed min_height_m");
  check(height_tolerance_m > 0.0 && height_tolerance_m < 0.01, "height_tolerance_m must lie in (0, 0.01) m");
  check(approach_band_m > 0.0 && approach_band_m < 0.05, "approach_band_m must lie in (0, 0.05) m");
  check(max_pressure_pa > 0.0 && std::isfinite(max_pressure_pa), "max_pressure_pa must be positive");
  check(load_filter_time_s > 0.0, "load_filter_time_s must be positive");
  check(settled_speed_m_s > 0.0, "settled_speed_m_s must be positive");
  check(integral_rate_per_s >= 0.0, "integral_rate_per_s must be >= 0");
  check(integral_limit_m >= 0.0, "integral_limit_m must be >= 0");
  check(move_threshold_m > 0.0, "move_threshold_m must be positive");
  check(damping_band_m > 0.0, "damping_band_m must be positive");
  check(hold_band_m >= height_tolerance_m && hold_band_m < 0.01,
        "hold_band_m must lie in [height_tolerance_m, 0.01) m");
  std::string s = err.str();
  if (s.size() >= 2) s.resize(s.size() - 2);
  return s;
}

HeightController::HeightController(const HeightControllerParams& params,
                                   std::shared_ptr<const CellCharacteristic> characteristic)
    : params_(params),
      characteristic_(std::move(characteristic)),
      load_(params.load_filter_time_s, characteristic_ ? characteristic_->params().plate_mass_kg : 0.0,
            characteristic_ ? characteristic_->params().plate_damping_n_s_m : 0.0) {
  if (characteristic_) supply_pressure_pa_ = characteristic_->params().supply_pressure_pa;
  if (characteristic_) shape_ = characteristic_->restShape();
  const std::string error = params_.validate();
  if (!error.empty()) throw std::invalid_argument("height controller parameters: " + error);
  if (!characteristic_) throw std::invalid_argument("height controller: no characteristic");
}

std::string HeightController::setParams(const HeightControllerParams& params) {
  const std::string error = params.validate();
  if (!error.empty()) return error;
  // The load estimate was filtered with the old time constant: a new one would mix two filters.
  if (params.load_filter_time_s != params_.load_filter_time_s)
    return "load_filter_time_s cannot change on a running controller";
  params_ = params;
  integral_m_ = std::clamp(integral_m_, -params_.integral_limit_m, params_.integral_limit_m);
  return "";
}

std::string HeightController::checkSetpoint(double height_m) const {
  std::ostringstream msg;
  if (!std::isfinite(height_m)) {
    msg << "height setpoint is not a finite number";
  } else if (height_m < params_.min_height_m || height_m > params_.max_height_m) {
    msg << "height setpoint " << height_m << " m is outside [" << params_.min_height_m << ", " << params_.max_height_m
        << "] m";
  }
  return msg.str();
}

void HeightController::setTarget(double height_m) {
  landing_.stop();  // a new aim: a new move if it is far
  has_target_ = true;
  target_m_ = height_m;
  integral_m_ = 0.0;
  holding_ = false;
}

void HeightController::clearTarget() {
  has_target_ = false;
  holding_ = false;
}

double HeightController::targetPressure() const {
  return characteristic_->pressureAt(target_m_, load_.load(), branch_);
}

bool HeightController::targetOutOfReach() const {
  const double p = targetPressure();
  return !(p <= params_.max_pressure_pa) || target_m_ > characteristic_->maxHeight(load_.load(), branch_);
}

double HeightController::fullFlowInvariantRate(int direction, double gauge_pressure_pa, double volume_m3) const {
  const CellParams& cell = characteristic_->params();
  const double p_abs = cell.ambient_pressure_pa + gauge_pressure_pa;
  const double flow =
      direction > 0
          ? orificeFlow(cell.gas, cell.inlet_area_m2, cell.ambient_pressure_pa + supply_pressure_pa_,
                        cell.supply_temperature_k, p_abs, cell.supply_temperature_k, cell.orifice_linear_band_pa)
                .mass_flow_kg_s
          : -orificeFlow(cell.gas, cell.vent_area_m2, p_abs, cell.ambient_temperature_k, cell.ambient_pressure_pa,
                         cell.ambient_temperature_k, cell.orifice_linear_band_pa)
                 .mass_flow_kg_s;
  return std::fabs(characteristic_->invariantRate(volume_m3, flow, cell.supply_temperature_k));
}

double HeightController::fullFlowRestRate(int direction, double gauge_pressure_pa, double volume_m3,
                                          double invariant) const {
  const double dk = 1e-3 * invariant;
  const double dh_dk = (characteristic_->restingHeight(invariant + dk, load_.load(), branch_) -
                        characteristic_->restingHeight(invariant - dk, load_.load(), branch_)) /
                       (2.0 * dk);
  return std::fabs(dh_dk) * fullFlowInvariantRate(direction, gauge_pressure_pa, volume_m3);
}

HeightController::MoveGauge HeightController::moveGauge(int direction, const Period& s) const {
  const double load = load_.load(), aim = target_m_ + integral_m_;
  const double aim_k = characteristic_->restInvariant(aim, load, branch_);
  const double rest_k = characteristic_->restInvariant(resting_height_m_ + in_flight_shift_m_, load, branch_);
  // The tail decides near the target: the valve's rate there (an unchoked inlet slows as the
  // cell's pressure rises).
  double p = characteristic_->pressureAt(aim, load, branch_), v = characteristic_->volumeAt(aim, load, branch_);
  if (!std::isfinite(p) || !std::isfinite(v)) p = s.gauge_pressure_pa, v = s.volume_m3;
  return {direction * (aim_k - rest_k), fullFlowInvariantRate(direction, p, v)};
}

double HeightController::halfPeriod() const {
  HalfPeriodCache& c = half_period_;
  if (c.half_period_s < 0.0 || c.target_m != target_m_ || c.branch != branch_ ||
      std::fabs(load_.load() - c.load_n) > 0.05 * c.load_n) {
    const double mass = std::max(characteristic_->params().plate_mass_kg, load_.load() / kGravity);
    const double k = characteristic_->plateStiffness(target_m_, load_.load(), branch_);
    c.half_period_s = k > 0.0 ? kPi * std::sqrt(mass / k) : 0.05;
    c.target_m = target_m_;
    c.load_n = load_.load();
    c.branch = branch_;
  }
  return c.half_period_s;
}

void HeightController::setDeadTime(double dead_time_s) { in_flight_.setDeadTime(dead_time_s); }

void HeightController::noteWritten(const ValveOpenings& cmd, double dt_s) { in_flight_.note(cmd, dt_s); }

double HeightController::inFlightRestShift(double gauge_pressure_pa, double volume_m3, double invariant) const {
  double inlet_s = 0.0, vent_s = 0.0;  // full-opening seconds still to act
  in_flight_.openSeconds(&inlet_s, &vent_s);
  double shift = 0.0;
  if (inlet_s > 0.0) shift += inlet_s * fullFlowRestRate(1, gauge_pressure_pa, volume_m3, invariant);
  if (vent_s > 0.0) shift -= vent_s * fullFlowRestRate(-1, gauge_pressure_pa, volume_m3, invariant);
  return shift;
}

ValveOpenings HeightController::update(double dt_s, double gauge_pressure_pa, double height_m) {
  Period s;
  s.dt_s = dt_s;
  s.gauge_pressure_pa = gauge_pressure_pa;
  s.height_m = height_m;
  predictRest(&s);
  if (!has_target_) {
    move_.stop();
    landing_.stop();
    return ValveOpenings{};
  }

  // Feedback: a resting height error is integrated into the height the predictor aims at.
  s.error_m = target_m_ - height_m;
  if (holding_ && !leavesHold(predictedError(), s.error_m, s.resting)) return ValveOpenings{};
  holding_ = false;
  if (s.resting && !moving() && std::fabs(s.error_m) > params_.height_tolerance_m * 0.5) {
    integral_m_ += params_.integral_rate_per_s * s.error_m * dt_s;
    integral_m_ = std::clamp(integral_m_, -params_.integral_limit_m, params_.integral_limit_m);
  }
  // Where the plate rests once the commands in flight have acted (a Smith predictor).
  s.predicted_error_m = predictedError();
  s.lowest = target_m_ <= params_.min_height_m + params_.height_tolerance_m;

  // A fold snapping: gas taken or given before it lands would stop it half way and drop the
  // plate back (the fold closes again); the error is corrected on the side it lands.
  const bool snap = snapping(s);
  if (snap) landing_.stop();
  if (landing_.active()) {
    if (const auto cmd = land(s)) return *cmd;
  }
  // Shaped full-flow move; its tail under feedback where the loop is fast enough.
  const bool starts = !moving() && std::fabs(s.predicted_error_m) > params_.move_threshold_m && !s.lowest;
  if (starts || move_.active()) {
    const int direction = starts ? (s.predicted_error_m > 0.0 ? 1 : -1) : move_.direction();
    const MoveGauge gauge = moveGauge(direction, s);
    if (starts) move_.start(direction, gauge.remaining);
    if (const auto opening = move_.step(dt_s, gauge.remaining, halfPeriod(), gauge.rate)) {
      const bool hand_over = move_.phase() == MovePhase::kFullFlow ? landingTakesOver(s, direction)
                             : move_.phase() == MovePhase::kTail   ? landingRate(dt_s) > 0.0
                                                                   : false;
      if (!hand_over) return command(s, direction, *opening);
      move_.stop();
      if (snap) return snapNudge(s);
      landing_.start();
      if (const auto cmd = land(s)) return *cmd;
    }
  }
  return snap ? snapNudge(s) : fineCorrection(s);
}

void HeightController::predictRest(Period* s) {
  const double dt_s = s->dt_s, gauge_pressure_pa = s->gauge_pressure_pa, height_m = s->height_m;
  const double speed = has_last_ && dt_s > 0.0 ? std::fabs(height_m - last_height_m_) / dt_s : 0.0;
  last_height_m_ = height_m;
  has_last_ = true;
  s->resting = speed < params_.settled_speed_m_s;

  // Load estimate: the plate's force balance on the structure's force at (h, p), outside moves
  // (a move plans with the load it started with) and with the plate off the bed (on the bed the
  // pressure says nothing about the load).
  // One solve of the film relaxed at the measured pressure gives both, and the fold's side.
  const CellCharacteristic::RelaxedCell relaxed = characteristic_->relaxedAt(height_m, gauge_pressure_pa, &shape_);
  branch_ = relaxed.branch;
  const bool weighable = height_m > 0.005 && gauge_pressure_pa > 0.0;
  load_.update(dt_s, height_m, weighable ? relaxed.load_n : 0.0, weighable && !move_.active());
  s->plate = tracker_.update(dt_s, height_m, plateAcceleration(relaxed.load_n, tracker_.state().velocity_m_s));

  // Where the plate rests if the valves shut now (adiabatic invariant of the present gas; the
  // volume uses the film relaxed at the measured pressure, so the invariant holds while the
  // plate swings).
  s->volume_m3 = relaxed.volume_m3;
  s->invariant = characteristic_->invariant(gauge_pressure_pa, s->volume_m3);
  resting_height_m_ = characteristic_->restingHeight(s->invariant, load_.load(), branch_);
  in_flight_shift_m_ = in_flight_.empty() ? 0.0 : inFlightRestShift(gauge_pressure_pa, s->volume_m3, s->invariant);
  // The fold's side is the film's relaxed one once the plate rests where that side puts it.
  if (s->resting && std::fabs(height_m - resting_height_m_) < params_.height_tolerance_m) settled_branch_ = branch_;
}

bool HeightController::snapping(const Period& s) {
  // The film's relaxed fold is on another side than the one the plate last rested on (the fold
  // is switching), or that side has no rest between the plate and where the gas would rest it
  // there (the plate is crossing a snap's gap).
  const double load = load_.load();
  const bool switching = branch_ != settled_branch_;
  const double rest = characteristic_->restingHeight(s.invariant, load, settled_branch_);
  if (!switching && (std::fabs(rest - s.height_m) <= params_.height_tolerance_m ||
                     !characteristic_->gapBetween(s.height_m, rest, load, settled_branch_))) {
    snap_time_s_ = snap_stalled_s_ = 0.0;
    return false;
  }
  if (snap_time_s_ == 0.0) snap_from_m_ = s.height_m;
  // Half way to the rest on the fold's new side the fold has passed its unstable middle: from
  // there the controller may brake the plate onto the target without stopping the snap.
  const double to = switching ? characteristic_->restingHeight(s.invariant, load, branch_) : rest;
  // Only a snap that sets in while the plate holds or tracks its target: a move through the
  // fold keeps its own braking (its landing), which the snap's overshoot needs.
  const bool snap = std::fabs(target_m_ - snap_from_m_) <= params_.move_threshold_m &&
                    std::fabs(s.height_m - snap_from_m_) <= 0.5 * std::fabs(to - snap_from_m_);
  // A snap is let run for kSnapTimeS at most (a stalled one is tipped on: snapNudge), and a
  // fold that never lands is corrected anyway.
  constexpr double kSnapTimeS = 2.0;
  snap_time_s_ = snap ? snap_time_s_ + s.dt_s : 0.0;
  if (!snap) snap_stalled_s_ = 0.0;  // each snap's stall is timed from its own start
  snap_direction_ = to > snap_from_m_ ? 1 : -1;
  return snap && snap_time_s_ <= kSnapTimeS;
}

ValveOpenings HeightController::snapNudge(const Period& s) {
  // A fold near its unstable middle can creep for seconds with the plate standing still, and
  // gas taken against the snap's direction folds it back (the plate drops by the whole snap):
  // a short pulse along it tips the fold over instead.
  constexpr double kStallS = 0.2, kNudgeOpening = 0.1;
  snap_stalled_s_ = s.resting ? snap_stalled_s_ + s.dt_s : 0.0;
  if (snap_stalled_s_ < kStallS) return ValveOpenings{};
  snap_stalled_s_ = 0.0;
  return command(s, snap_direction_, kNudgeOpening);
}

ValveOpenings HeightController::command(const Period& s, int direction, double opening) const {
  ValveOpenings cmd;
  if (direction > 0) {
    cmd.inlet = s.gauge_pressure_pa < params_.max_pressure_pa ? opening : 0.0;
  } else {
    cmd.vent = s.lowest ? 1.0 : opening;  // lowest setpoint: empty as fast as the vent allows
  }
  return cmd;
}

double HeightController::landingRate(double dt_s) const {
  // A critically damped loop of rate r with a delay d keeps its margin while r d <= 1/4.
  constexpr double kDelayRadians = 0.25;
  // The tracked speed's noise times 2 r m is force the landing asks of the gas: at most a
  // quarter of the load.
  constexpr double kForceNoiseShare = 0.25;
  const double own = kPi / halfPeriod();
  double loop = kDelayRadians / (dt_s + in_flight_.deadTime());
  const double speed_sd = tracker_.speedSd(height_noise_m_, dt_s);
  if (speed_sd > 0.0) {
    const PlateMechanics m = mechanics();
    loop = std::min(loop, kForceNoiseShare * m.load_n / (2.0 * m.mass_kg * speed_sd));
  }
  return loop >= own ? std::min(2.0 * own, loop) : 0.0;
}

PlateMechanics HeightController::mechanics() const {
  const CellParams& cell = characteristic_->params();
  const double load = load_.load();
  return {load, std::max(cell.plate_mass_kg, load / kGravity), cell.plate_damping_n_s_m};
}

double HeightController::plateAcceleration(double structure_force_n, double velocity_m_s) const {
  const PlateMechanics m = mechanics();
  return (structure_force_n - m.load_n - m.damping_n_s_m * velocity_m_s) / m.mass_kg;
}

std::optional<double> HeightController::landingGas(const Period& s, double force_n) const {
  const double p = characteristic_->pressureAt(s.height_m, force_n, branch_);
  const double v = characteristic_->volumeAt(s.height_m, force_n, branch_);
  if (!std::isfinite(p) || !std::isfinite(v)) return std::nullopt;
  return characteristic_->invariant(p, v) - s.invariant;
}

bool HeightController::landingTakesOver(const Period& s, int direction) const {
  // On the bed the structure's force says nothing of the plate's; before the plate is under
  // way the landing would only wait for it.
  const double rate = landingRate(s.dt_s);
  if (!(rate > 0.0) || s.height_m <= 0.005 || direction * s.plate.velocity_m_s <= 0.0) return false;
  const auto gas = landingGas(s, PlateLanding::approachForce(s.plate, target_m_ + integral_m_, mechanics(), rate));
  return gas && direction * *gas < fullFlowInvariantRate(direction, s.gauge_pressure_pa, s.volume_m3) * s.dt_s;
}

std::optional<ValveOpenings> HeightController::land(const Period& s) {
  const double rate = landingRate(s.dt_s);  // the load estimate moves it: it may drop out
  const auto force =
      rate > 0.0 ? landing_.force(s.dt_s, s.plate, target_m_ + integral_m_, mechanics(), rate) : std::nullopt;
  const auto gas = force ? landingGas(s, *force) : std::nullopt;
  if (!gas) {
    landing_.stop();
    return std::nullopt;
  }
  const int direction = *gas > 0.0 ? 1 : -1;
  const double full = fullFlowInvariantRate(direction, s.gauge_pressure_pa, s.volume_m3);
  return command(s, direction, full > 0.0 ? std::clamp(std::fabs(*gas) / (full * s.dt_s), 0.0, 1.0) : 0.0);
}

ValveOpenings HeightController::fineCorrection(const Period& s) {
  if (s.lowest) return command(s, -1, 1.0);
  const double swing = s.height_m - resting_height_m_;  // the swing about the gas's rest now
  // Active damping lags the swing by the valves' dead time too: past an eighth of the plate's
  // period it hardly damps, at a quarter it pumps. The loop's delay exceeds the valves' dead
  // time (a bus cycle's wait, the readings' age), so beyond a sixteenth the cell holds on the
  // gas alone and the swing rings out on the plate's own damping (on the Modbus bed: every
  // cell; the simulated one, without dead time, damps).
  const bool damp_swing = in_flight_.deadTime() < 0.125 * halfPeriod();
  const double tolerance = params_.height_tolerance_m;
  const bool on_target = damp_swing ? std::fabs(s.error_m) < tolerance && std::fabs(swing) < tolerance
                                    : !s.resting || std::fabs(s.error_m) < tolerance;
  if (std::fabs(s.predicted_error_m) < tolerance && on_target) {
    holding_ = true;  // the gas rests the plate on target (where the swing is damped: and it has rung out)
    return ValveOpenings{};
  }
  const double demand =
      s.predicted_error_m / params_.approach_band_m + (damp_swing ? swing / params_.damping_band_m : 0.0);
  return command(s, demand > 0.0 ? 1 : -1, std::clamp(std::fabs(demand), 0.0, 1.0));
}

bool HeightController::leavesHold(double predicted_error_m, double error_m, bool resting) const {
  // The gas decides where the plate rests: the prediction is the test while it swings; the
  // measured height only at rest, where the swing does not enter it.
  return std::fabs(predicted_error_m) > params_.hold_band_m || (resting && std::fabs(error_m) > params_.hold_band_m);
}

double flowLimitedMinimumTime(const CellParams& params, double load_n, double from_m, double to_m) {
  const StructureEquilibrium target = makeCellStructure(params)->equilibriumAtHeight(to_m, load_n);
  if (!target.converged) return std::nan("");
  CellModel plant(params);
  plant.resetToEquilibrium(from_m, load_n);
  CellInputs in;
  in.load_n = load_n;
  const bool up = to_m > from_m;
  in.inlet_opening = up ? 1.0 : 0.0;
  in.vent_opening = up ? 0.0 : 1.0;
  const double step = 2e-4;
  double previous = plant.variables().structure.volume_m3;
  while (plant.time() < 30.0) {
    plant.advance(step, in);
    const double v = plant.variables().structure.volume_m3;
    if (up ? v >= target.eval.volume_m3 : v <= target.eval.volume_m3) {
      // Interpolate the crossing inside the last step.
      const double f = (target.eval.volume_m3 - previous) / (v - previous);
      return plant.time() - step + std::clamp(f, 0.0, 1.0) * step;
    }
    previous = v;
  }
  return std::nan("");
}

}  // namespace nursing_bed
