#include "nursing_bed/core/control/gas_verifier.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/io/errors.h"

namespace nursing_bed {

Status GasVerifierParams::validate() const {
  ErrorList errors;
  errors.addIf(!(resume_vent_s >= 0.0 && resume_vent_s <= 0.2),
               "resume_vent_s must lie in [0, 0.2] s (a check, not a vent), got ", resume_vent_s);
  errors.addIf(!(reanchor_below_m >= 0.0 && std::isfinite(reanchor_below_m)), "reanchor_below_m must be >= 0, got ",
               reanchor_below_m);
  errors.addIf(!(recount_doubt_m >= 0.0 && std::isfinite(recount_doubt_m)), "recount_doubt_m must be >= 0, got ",
               recount_doubt_m);
  errors.addIf(!(flag_doubt_m >= 0.0 && std::isfinite(flag_doubt_m)), "flag_doubt_m must be >= 0, got ", flag_doubt_m);
  errors.addIf(!(recount_max_load_n > 0.0 && std::isfinite(recount_max_load_n)),
               "recount_max_load_n must be finite and > 0, got ", recount_max_load_n);
  errors.addIf(!(verify_hold_s >= 0.0 && verify_hold_s <= 2.0), "verify_hold_s must lie in [0, 2] s, got ",
               verify_hold_s);
  errors.addIf(!(link_steady_s >= 0.0 && link_steady_s <= 10.0), "link_steady_s must lie in [0, 10] s, got ",
               link_steady_s);
  errors.addIf(!(verify_tolerance_pa > 0.0 && std::isfinite(verify_tolerance_pa)),
               "verify_tolerance_pa must be finite and > 0, got ", verify_tolerance_pa);
  errors.addIf(!(verify_tolerance_rel >= 0.0 && verify_tolerance_rel < 1.0),
               "verify_tolerance_rel must lie in [0, 1), got ", verify_tolerance_rel);
  errors.addIf(!(prove_hold_s >= 0.0 && prove_hold_s <= 30.0), "prove_hold_s must lie in [0, 30] s, got ",
               prove_hold_s);
  errors.addIf(!(prove_settle_s >= 0.0 && prove_settle_s <= 5.0), "prove_settle_s must lie in [0, 5] s, got ",
               prove_settle_s);
  errors.addIf(!(prove_tolerance_pa > 0.0 && std::isfinite(prove_tolerance_pa)),
               "prove_tolerance_pa must be finite and > 0, got ", prove_tolerance_pa);
  errors.addIf(!(prove_tolerance_rel >= 0.0 && prove_tolerance_rel < 1.0),
               "prove_tolerance_rel must lie in [0, 1), got ", prove_tolerance_rel);
  errors.addIf(!(prove_min_height_m >= 0.0 && std::isfinite(prove_min_height_m)),
               "prove_min_height_m must be finite and >= 0, got ", prove_min_height_m);
  return errors.status();
}

namespace {
const GasVerifierParams& validated(const GasVerifierParams& p) {
  const Status valid = p.validate();
  if (!valid.ok()) throw std::invalid_argument("gas check parameters: " + valid.message());
  return p;
}

GasProofParams proofParams(const GasVerifierParams& p) {
  GasProofParams q;
  q.hold_s = p.prove_hold_s;
  q.settle_s = p.prove_settle_s;
  q.tolerance_pa = p.prove_tolerance_pa;
  q.tolerance_rel = p.prove_tolerance_rel;
  q.min_height_m = p.prove_min_height_m;
  return q;
}
}  // namespace

GasVerifier::GasVerifier(const GasVerifierParams& params) : params_(validated(params)), proof_(proofParams(params_)) {}

void GasVerifier::reset(bool verified) {
  gas_ = verified ? GasKnowledge::kKnown : GasKnowledge::kUnverified;
  found_flat_ = false;
  recounting_ = false;
  doubtful_ = false;
  check_pending_ = false;
  check_vent_left_s_ = 0.0;
  check_until_s_ = -1.0;
  check_reanchored_ = false;
  link_lost_ = false;
  reference_pa_ = std::numeric_limits<double>::quiet_NaN();
  link_hold_.left_s = 0.0;
  hold_mismatch_ = false;
  proof_.reset();
}

void GasVerifier::linkLost(double reference_pa) {
  link_lost_ = true;
  reference_pa_ = reference_pa;
  check_pending_ = false;
  link_hold_.left_s = 0.0;
  check_vent_left_s_ = 0.0;
  check_until_s_ = -1.0;
}

void GasVerifier::linkRestored(double now_s) {
  link_up_since_s_ = now_s;
  check_pending_ = params_.resume_vent_s > 0.0 || (params_.verify_hold_s > 0.0 && std::isfinite(reference_pa_));
  if (!check_pending_) link_lost_ = false;
}

void GasVerifier::suspect() {
  // Anchoring and finding already vent to flat; a known gas is found again the same way.
  if (gas_ == GasKnowledge::kKnown || gas_ == GasKnowledge::kAnchoring) gas_ = GasKnowledge::kUnverified;
  found_flat_ = false;
}

void GasVerifier::suspectInconsistent() {
  suspect();
  proof_.start();
}

void GasVerifier::noteHold(bool holding, double gauge_pressure_pa, double height_m, double dt_s) {
  // Found flat proves the count from there, not the valves (GasProof). Either verdict sends the
  // cell flat again: a failed hold to be proved again, a passed one because a fault that ended
  // during the refill (a vent open against the inlet) left its gas uncounted.
  if (!proving()) return;
  if (proof_.update(holding, gauge_pressure_pa, height_m, dt_s) != GasProof::Verdict::kNone) suspect();
}

bool GasVerifier::gasUnknown() const {
  if (gas_ == GasKnowledge::kUnverified || gas_ == GasKnowledge::kFinding) return true;
  return link_lost_ || check_pending_ || link_hold_.left_s > 0.0 || check_vent_left_s_ > 0.0 || check_until_s_ >= 0.0;
}

void GasVerifier::note(const ObserverEvents& events) {
  if (!events.reanchored) return;
  found_flat_ = true;
  check_reanchored_ = true;
}

void GasVerifier::heightRequested(double target_m, double height_m) {
  // Near the bag's top 1 % of gas moves a light plate 8-10 mm, and pressure alone cannot tell
  // a plate higher than counted from a heavier load on it: each move's count error stays in the
  // inventory until the cell is found flat. A cell lowered into the low band has little height
  // to lose there, so it passes through flat on the way.
  const double band = params_.reanchor_below_m;
  const bool low = target_m <= band;
  if (gas_ == GasKnowledge::kAnchoring && !low && !recounting_) {
    gas_ = GasKnowledge::kKnown;  // raised again before it was found flat
  } else if (gas_ == GasKnowledge::kKnown && low && band > 0.0 && height_m > band) {
    gas_ = GasKnowledge::kAnchoring;
    found_flat_ = false;
  }
}

void GasVerifier::pressureRequested() {
  if (gas_ == GasKnowledge::kAnchoring) gas_ = GasKnowledge::kKnown;
  recounting_ = false;
}

void GasVerifier::noteCountDoubt(double doubt_m, double load_n) {
  // Near the bag's top a light plate's height moves 5-15 mm per 1 % of gas, and pressure alone
  // cannot tell a higher plate from a heavier load: a doubtful count is ended where the gas is
  // measured, on the flat cell.
  doubtful_ = params_.flag_doubt_m > 0.0 && doubt_m > params_.flag_doubt_m;
  if (gas_ != GasKnowledge::kKnown || !(params_.recount_doubt_m > 0.0) || !(doubt_m > params_.recount_doubt_m) ||
      !(load_n < params_.recount_max_load_n))
    return;
  gas_ = GasKnowledge::kAnchoring;
  found_flat_ = false;
  recounting_ = true;
}

ValveOpenings GasVerifier::linkCheckValves(double now_s, double period_s, double gauge_pressure_pa,
                                           CellObserver* observer, const ValveOpenings& wanted) {
  // Over a lost link the gas is unverified: the bed may have been emptied meanwhile (a restarted
  // terminal, a CPR dump). Pressure cannot tell: a sealed flat cell under a load floats its
  // plate on its residual gas at the pressure a cell lifted under a fraction of the load reads,
  // and with the controller holding quietly on target nothing tells them apart. Venting does:
  // the floating flat cell grounds and reads ambient within a few tens of ms, and the observer's
  // re-anchor test takes it with the valves shut; a lifted cell keeps its load's pressure and
  // loses 1-3 mm, which the controller restores after the check.
  const CellObserverParams& op = observer->params();
  if (check_pending_ && now_s - link_up_since_s_ < params_.link_steady_s) return ValveOpenings{};
  if (check_pending_) {
    check_pending_ = false;
    check_reanchored_ = false;
    link_hold_.sum_pa = 0.0;
    link_hold_.count = 0;
    // Without a pressure from before the loss there is nothing to compare: the vent check only.
    link_hold_.left_s = std::isfinite(reference_pa_) ? params_.verify_hold_s : 0.0;
    if (link_hold_.left_s <= 0.0) startVentCheck();
  }
  if (link_hold_.left_s > 0.0) return holdValves(period_s, gauge_pressure_pa);
  if (check_vent_left_s_ > 0.0) {
    const bool grounded = gauge_pressure_pa < observer->flatPressure();
    const double opening = grounded ? 0.0 : std::min(1.0, check_vent_left_s_ / period_s);
    check_vent_left_s_ = grounded ? 0.0 : std::max(0.0, check_vent_left_s_ - period_s);
    // The test's mean pressure starts above the flat cell's: twice its time, after the dead time.
    if (check_vent_left_s_ <= 0.0) {
      check_until_s_ = now_s + period_s + op.valve_dead_time_s + 2.0 * op.reanchor_time_s;
      observer->expectFlat(check_until_s_ - now_s);
    }
    return ValveOpenings{0.0, opening};
  }
  if (check_until_s_ < 0.0) {
    if (check_vent_left_s_ <= 0.0 && link_hold_.left_s <= 0.0) link_lost_ = false;
    return wanted;
  }
  // Found flat (re-anchored), the controller takes over at once; else after the test's time.
  if (now_s < check_until_s_ && !check_reanchored_) return ValveOpenings{};
  check_until_s_ = -1.0;
  link_lost_ = false;
  return wanted;
}

void GasVerifier::startVentCheck() {
  check_vent_left_s_ = params_.resume_vent_s;
  if (check_vent_left_s_ <= 0.0) link_lost_ = false;
}

ValveOpenings GasVerifier::holdValves(double period_s, double gauge_pressure_pa) {
  // The gas and the height kept over the loss, under the load kept, read the pressure they
  // read before it. A terminal that restarted empty (or a cell emptied meanwhile) reads its
  // own: pressure alone cannot tell a sealed flat cell floating its plate from a lifted one,
  // but it can tell either from the cell the observer kept.
  if (std::isfinite(gauge_pressure_pa)) {
    link_hold_.sum_pa += gauge_pressure_pa;
    ++link_hold_.count;
  }
  link_hold_.left_s = std::max(0.0, link_hold_.left_s - period_s);
  if (link_hold_.left_s > 0.0) return ValveOpenings{};
  const double mean = link_hold_.count > 0 ? link_hold_.sum_pa / link_hold_.count : reference_pa_;
  const double tolerance =
      std::max(params_.verify_tolerance_pa, params_.verify_tolerance_rel * std::fabs(reference_pa_));
  hold_mismatch_ = std::fabs(mean - reference_pa_) > tolerance;
  if (hold_mismatch_) {
    suspect();  // found again by venting flat (findingValves)
    link_lost_ = false;
  } else {
    startVentCheck();
  }
  return ValveOpenings{};
}

ValveOpenings GasVerifier::findingValves(double period_s, CellObserver* observer, const ValveOpenings& wanted,
                                         bool* found_after_vent) {
  // Started flat over a cell that holds gas, the observer would count every fill from nothing
  // and fill the cell to the bag's top. Its pressure alone cannot give its gas (nor its height
  // or load); a flat cell's can. So it vents, the one safe direction, until the observer's
  // re-anchor test finds it flat (below ambient counts: a heavy plate's vented cell settles
  // there), and is then controlled to its kept setpoint. A cell anchoring does the same with
  // its height tracked meanwhile.
  *found_after_vent = false;
  if (gas_ == GasKnowledge::kKnown) return wanted;
  if (found_flat_) {
    const bool vented = gas_ != GasKnowledge::kUnverified;
    gas_ = GasKnowledge::kKnown;
    recounting_ = false;
    if (!vented) return wanted;  // found flat before any command (a bed started flat)
    *found_after_vent = true;
    return ValveOpenings{};
  }
  if (gas_ == GasKnowledge::kUnverified) gas_ = GasKnowledge::kFinding;
  observer->expectFlat(2.0 * period_s);
  return ValveOpenings{0.0, 1.0};
}

}  // namespace nursing_bed
