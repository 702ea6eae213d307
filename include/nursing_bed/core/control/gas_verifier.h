// What the control side knows of a cell's gas where the height comes from the observer
// (ROS-free): whether the observer's gas inventory can be trusted, and the valve filters that
// make it trustworthy again (vent until the observer finds the cell flat; after a lost link, a
// short vent and a re-anchor test). AirbagCell applies them after its mode's valves.
#pragma once

#include <limits>
#include <string>

#include "nursing_bed/core/control/gas_proof.h"
#include "nursing_bed/core/io/status.h"
#include "nursing_bed/core/observer/cell_observer.h"
#include "nursing_bed/core/physics/valve_openings.h"

namespace nursing_bed {

/// The gas check's knobs. Their parameter keys stay under observer/ (config/observer.yaml),
/// where users set them with the observer's re-anchor test they drive.
struct GasVerifierParams {
  /// After a lost link the cell vents at most this long (until its pressure reads flat), then
  /// keeps both valves shut while the observer's re-anchor test runs; 0: no check [s].
  double resume_vent_s = 0.05;
  /// A height target at or below this, sent while the cell's height is above it, is reached
  /// through a flat cell: the cell vents until the re-anchor test finds it flat, then fills to
  /// the target. The gas the moves before left uncounted is gone before the low hold and the
  /// next rise; 0: never [m].
  double reanchor_below_m = 0.035;
  /// A cell whose counted vent gas may be off by more than this height (the observer's
  /// count_doubt_m) is re-anchored the same way at its kept target: it vents until the
  /// re-anchor test finds it flat, its height tracked, then fills to the target; 0: never [m].
  double recount_doubt_m = 0.004;
  /// A cell whose counted vent gas may be off by more than this height reports its height
  /// unverified until the doubt ends (found flat): the doubt bounds the count's error, and one
  /// too large to promise 6 mm is said, not hidden. The cell is controlled meanwhile; 0: never [m].
  double flag_doubt_m = 0.003;
  /// Only a cell whose load estimate is below this is re-anchored for its count's doubt: one
  /// that carries little more than its plate (0.6 N), where a flat cell moves no load; one the
  /// body touches (a head's cradle, a bony prominence) keeps its count [N].
  double recount_max_load_n = 1.5;
  /// After a lost link both valves stay shut this long and the mean pressure is compared
  /// with the last one before the loss: the gas kept at the height kept holds the load kept
  /// at that pressure. Outside the tolerance the gas is found again by venting flat; 0: no
  /// comparison [s].
  double verify_hold_s = 0.2;
  /// The checks after a lost link wait, both valves shut, until the link has stayed up this
  /// long: over a link that drops replies a written vent lasts until the terminal's watchdog,
  /// not as commanded, and a light plate rung by such vents reads flat while lifted; 0: at
  /// once [s].
  double link_steady_s = 1.0;
  /// The comparison's tolerance: the larger of this and verify_tolerance_rel of the pressure
  /// before the loss [Pa].
  double verify_tolerance_pa = 300.0;
  double verify_tolerance_rel = 0.15;  ///< see verify_tolerance_pa [-]
  /// After an inconsistency the cell found flat is refilled but stays unverified until a hold
  /// at height proves its gas: the valves held (shut, or a hold's small corrections) this long
  /// after prove_settle_s with the plate above prove_min_height_m, the mean pressure of its
  /// second half within the tolerance of its first half's. A plate sinking on a vent stuck open
  /// fails it (and is vented flat again). A hold that keeps its pressure sends the cell flat
  /// once more (a fault that ended during the refill left gas uncounted), after which it is
  /// trusted; 0: found flat proves the gas [s].
  double prove_hold_s = 2.0;
  double prove_settle_s = 0.3;  ///< the plate rings this long after a valve edge before the hold counts [s]
  /// The hold's tolerance: the larger of this and prove_tolerance_rel of its first half's mean [Pa].
  double prove_tolerance_pa = 100.0;
  double prove_tolerance_rel = 0.05;  ///< see prove_tolerance_pa [-]
  /// Only a hold with the estimate above this proves the gas (a flat cell shows no leak) [m].
  double prove_min_height_m = 0.015;

  /// Success when valid, else an error with every problem found, separated by "; ".
  Status validate() const;
};

/// What the observer's gas is worth: known (a simulated plant reset with it, a height given, a
/// height sensor, or the cell since found flat), unverified (reset flat over real hardware, not
/// yet found flat), being found (commanded meanwhile: venting, height unknown), or being
/// re-anchored (lowered into the low band: venting, height tracked).
enum class GasKnowledge : std::uint8_t { kKnown, kUnverified, kFinding, kAnchoring };

// size: ~27 methods are one knowledge state's events and queries (link, fault, target, count's
// doubt) and its two valve filters; the proof's hold is its own class (GasProof).
class GasVerifier {
 public:
  /// Throws std::invalid_argument naming what is wrong in `params`.
  explicit GasVerifier(const GasVerifierParams& params);
  const GasVerifierParams& params() const { return params_; }

  /// A reset: the gas is known, or (`verified` false: reset flat over real hardware without a
  /// height sensor, which keeps its gas through a node restart) to be found flat before it is
  /// trusted. Any check under way is dropped.
  void reset(bool verified);
  /// Takes the observer's findings of one step (a re-anchor ends a search for the flat cell).
  void note(const ObserverEvents& events);
  /// The link is lost; `reference_pa` is the mean pressure before (NaN: unknown). The gas is
  /// unverified until the check after the link is back.
  void linkLost(double reference_pa);
  /// The link is back at `now_s`: the gas is checked before the controller acts again, once
  /// the link has stayed up link_steady_s (a hold compared with the pressure before the loss,
  /// then resume_vent_s).
  void linkRestored(double now_s);
  /// Something showed the gas inventory wrong (a device or sensor fault): unverified until the
  /// cell is found flat again; it vents to flat when commanded.
  void suspect();
  /// The readings contradicted the gas (a consistency monitor): as suspect(), and once found
  /// flat and refilled still unverified until a hold at height proves the valves keep the gas
  /// (prove_hold_s), then found flat once more.
  void suspectInconsistent();
  /// One period of the readings for the proof's hold: `holding` when the valves are shut or
  /// only correct the hold, `height_m` the estimate. A failed hold suspects the gas again.
  void noteHold(bool holding, double gauge_pressure_pa, double height_m, double dt_s);
  /// A new height target `target_m` while the (tracked) height is `height_m`: lowered into the
  /// low band from above it, the cell is to pass through flat; raised out of it before that, it
  /// need not.
  void heightRequested(double target_m, double height_m);
  /// A pressure setpoint is held from where the cell is: no re-anchoring on the way.
  void pressureRequested();
  /// The height `doubt_m` the observer's vent count may be off by, on a cell carrying `load_n`:
  /// beyond flag_doubt_m the count is doubtful; beyond recount_doubt_m, below
  /// recount_max_load_n, a known gas is re-anchored (kAnchoring until found flat, whatever
  /// targets come meanwhile).
  void noteCountDoubt(double doubt_m, double load_n);
  /// Anchoring because of the count's doubt (not a target in the low band).
  bool recounting() const { return recounting_ && gas_ == GasKnowledge::kAnchoring; }

  GasKnowledge knowledge() const { return gas_; }
  /// The gas (and the height from it) is not proven: lost link not yet checked, suspected, or
  /// reset over real hardware and not yet found flat, or found flat after an inconsistency and
  /// not yet proved by a hold at height; or its count is doubtful, or being recounted (venting
  /// to be found flat: the doubt in millimetres shrinks with the estimate on the way down,
  /// while the gas it doubts is still uncounted, and a vent that passes nothing leaves the
  /// estimate falling to flat under a lifted plate).
  bool unverified() const { return unproven() || doubtful_ || recounting(); }
  /// The gas is not proven (as unverified(), without a doubtful count).
  bool unproven() const { return gasUnknown() || proof_.pending(); }
  /// The observer's count doubt (noteCountDoubt) is beyond flag_doubt_m: the height is reported
  /// unverified, the cell still controlled.
  bool doubtful() const { return doubtful_; }
  /// Unverified and not yet found flat (or the link check under way): the cell is then never
  /// inflated, only held or vented, and its height is no reference for the landed test.
  bool gasUnknown() const;
  /// Found flat after an inconsistency, refilled, and waiting for a hold that proves the gas.
  bool proving() const { return proof_.pending() && gas_ == GasKnowledge::kKnown; }
  /// Holds that failed to prove the gas since the last reset.
  int failedProofs() const { return proof_.failures(); }
  /// The last link check's hold found the pressure inconsistent with the gas kept.
  bool holdMismatched() const { return hold_mismatch_; }
  /// Commanded before the observer found the cell flat after a reset: its gas (and height) is
  /// unknown, and it vents flat before it is controlled.
  bool findingGas() const { return gas_ == GasKnowledge::kFinding; }
  /// Lowered into the low band: venting flat so that the observer re-anchors its gas, the target
  /// kept; its height is still tracked.
  bool anchoringGas() const { return gas_ == GasKnowledge::kAnchoring; }

  /// Valve filter after a lost link: a short vent, then both valves shut while the observer's
  /// re-anchor test runs; otherwise `wanted`. `gauge_pressure_pa` is the last reading.
  ValveOpenings linkCheckValves(double now_s, double period_s, double gauge_pressure_pa, CellObserver* observer,
                                const ValveOpenings& wanted);
  /// Valve filter while the gas is not known: a full vent until the observer re-anchors the
  /// flat cell; otherwise `wanted`. `*found_after_vent` is set when the cell was just found
  /// flat after venting for it (the controller's integral ran on the vent: restart it).
  ValveOpenings findingValves(double period_s, CellObserver* observer, const ValveOpenings& wanted,
                              bool* found_after_vent);

 private:
  /// The short vent of the link check (resume_vent_s) begins.
  void startVentCheck();
  /// The comparison's hold: both valves shut; at its end the gas is suspected or the vent
  /// check begins.
  ValveOpenings holdValves(double period_s, double gauge_pressure_pa);

  GasVerifierParams params_;
  GasKnowledge gas_ = GasKnowledge::kKnown;
  bool found_flat_ = false;         ///< re-anchored since the search (or the anchoring) began
  bool recounting_ = false;         ///< the anchoring was started by the count's doubt
  bool doubtful_ = false;           ///< the count's doubt is beyond flag_doubt_m
  bool check_pending_ = false;      ///< the link came back: the gas is to be checked
  double link_up_since_s_ = 0.0;    ///< when the link came back [s]
  double check_vent_left_s_ = 0.0;  ///< full-vent time of the check still to command [s]
  double check_until_s_ = -1.0;     ///< valves kept shut until then for the re-anchor test [s]
  bool check_reanchored_ = false;   ///< re-anchored since the check's test began
  bool link_lost_ = false;          ///< the link was lost and the check has not ended
  double reference_pa_ =
      std::numeric_limits<double>::quiet_NaN();  ///< mean pressure before the loss (NaN: unknown) [Pa]
  /// The link check's comparison hold.
  struct LinkHold {
    double left_s = 0.0;  ///< time of the hold still to run [s]
    double sum_pa = 0.0;  ///< readings summed over the hold
    long count = 0;
  };
  LinkHold link_hold_;
  bool hold_mismatch_ = false;  ///< the last hold did not match the pressure before the loss
  GasProof proof_;              ///< the hold that proves the gas after an inconsistency
};

}  // namespace nursing_bed
