// The proof of a cell's gas after an inconsistency (ROS-free): found flat proves the count from
// there, not the valves, so the refilled cell is trusted only once a hold at height keeps its
// pressure. GasVerifier owns one and acts on its verdicts.
#pragma once

#include <cstdint>

namespace nursing_bed {

/// The proof's hold. Its parameter keys are GasVerifierParams' prove_* (validated there).
struct GasProofParams {
  double hold_s = 2.0;          ///< the hold's length after the settling; 0: no proof asked [s]
  double settle_s = 0.3;        ///< the plate rings this long after a valve edge before the hold counts [s]
  double tolerance_pa = 100.0;  ///< the halves' means agree within the larger of this ... [Pa]
  double tolerance_rel = 0.05;  ///< ... and this fraction of the first half's mean [-]
  double min_height_m = 0.015;  ///< only a hold with the estimate above this counts (a flat cell shows no leak) [m]
};

/// One job: whether a hold at height proves that the valves keep the gas. Held (valves shut, or
/// only a hold's corrections) for settle_s + hold_s with the plate lifted, the mean pressure of
/// the hold's second half must lie within the tolerance of its first half's: gas that leaves
/// (or enters) moves the pressure along the structure at a rate no constant load does.
class GasProof {
 public:
  enum class Verdict : std::uint8_t { kNone, kProved, kFailed };

  explicit GasProof(const GasProofParams& params) : params_(params) {}

  /// An inconsistency: a proof is asked (none when hold_s is 0), its hold from the start.
  void start();
  /// No proof asked, the failures forgotten.
  void reset();
  /// A proof is asked and not yet given.
  bool pending() const { return pending_; }
  /// Holds that failed since the last reset.
  int failures() const { return failures_; }
  /// One period of the readings while a proof is pending: `holding` when the valves are shut or
  /// only correct the hold, `height_m` the estimate. kProved ends the proof; kFailed keeps it
  /// pending with its hold from the start.
  Verdict update(bool holding, double gauge_pressure_pa, double height_m, double dt_s);

 private:
  struct Hold {
    double held_s = 0.0;                     ///< held this long, the settling included [s]
    double first_pa = 0.0, second_pa = 0.0;  ///< the readings summed over each half
    long first_n = 0, second_n = 0;
  };
  GasProofParams params_;
  bool pending_ = false;
  Hold hold_;
  int failures_ = 0;
};

}  // namespace nursing_bed
