// Posture plans of the bed manager (ROS-free): a nurse's intent turned into a height for every
// cell over time. Each plan validates its parameters when it is made; every target it gives is
// inside the configured height limits. doc/bed_manager.md lists plans and parameters.
#pragma once

#include <cstddef>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "nursing_bed/core/bed/adaptive_support.h"
#include "nursing_bed/core/bed/bed_grid.h"
#include "nursing_bed/core/io/param_table.h"
#include "nursing_bed/core/io/status.h"

namespace nursing_bed {

/// The absolute cap on a lateral turn, whatever the configuration says [deg].
constexpr double kHardMaxTiltDeg = 40.0;

/// Plan configuration (config/bed_manager.yaml, `plans/...`).
struct PlanConfig {
  double nominal_height_m = 0.10;    ///< flat bed height [m]
  double min_height_m = 0.02;        ///< lowest height a plan commands (CPR vents instead) [m]
  double max_height_m = 0.15;        ///< highest height a plan commands [m]
  double max_tilt_deg = 30.0;        ///< configured maximum lateral turn [deg] (<= 40)
  double max_tilt_rate_deg_s = 1.0;  ///< fastest change of the turn angle [deg/s]
  /// Fraction of max_tilt_rate_deg_s at which the bed's own slope under the trunk may change:
  /// the patient rolls faster than the bed's slope (he follows the cells' lag and shifting
  /// contact; measured up to 1.83 times at a plan switch, doc/safety.md) [-].
  double bed_tilt_rate_fraction = 0.5;
  double turn_ramp_s = 60.0;              ///< default ramp time of a turn [s]
  double turn_dwell_s = 600.0;            ///< default dwell at the turned angle [s]
  double alternating_period_s = 600.0;    ///< default alternating cycle [s]
  double alternating_low_m = 0.03;        ///< default height of the relieved (low) cells [m]
  double alternating_high_m = 0.12;       ///< default height of the supporting cells [m]
  double alternating_transition_s = 5.0;  ///< the rising group gets this long before the next one lowers [s]
  int static_head_rows = 2;               ///< head rows that alternating leaves at the nominal height
  double max_inflate_timeout_s = 900.0;   ///< default time before max_inflate reverts [s]
  AdaptiveSupportParams adaptive;         ///< the adaptive plan's defaults (`plans/adaptive/...`)
  /// Success when valid, else an error with every problem found, separated by "; ".
  Status validate() const;
};

/// Where the body lies, so that plans act under it (from the simulator's body model, or the
/// default adult placement).
struct BodyFootprint {
  int first_row = 0;        ///< first row under the body (head end)
  int last_row = 17;        ///< last row under the body (feet)
  double center_y_m = 0.0;  ///< the body's midline across the bed [m]
};

/// The kinds of plan. Requests and the saved resume record name them by planKindName(); inside
/// the core they are compared as this type only.
enum class PlanKind { kFlat, kLateralTurn, kAlternating, kMaxInflate, kCpr, kCustom, kSafeLevel, kAdaptive };

/// The name a plan kind has in requests, ~state and the resume record ("flat", "lateral_turn",
/// "alternating", "max_inflate", "cpr", "custom", "safe_level", "adaptive").
std::string planKindName(PlanKind kind);
/// The kind named `name`; nullopt when no kind has that name.
std::optional<PlanKind> planKindFromName(const std::string& name);

/// What a plan wants at one instant.
struct PlanTargets {
  std::vector<double> heights_m;  ///< per cell id; empty when venting
  bool vent_all = false;          ///< open every vent (CPR)
  std::string phase;              ///< e.g. "ramp", "dwell", "group 2 of 3 low"
  double tilt_deg = 0.0;          ///< lateral turn angle commanded now (+: towards the patient's left)
  bool finished = false;          ///< the plan has run its course (max_inflate: revert now)
};

/// A request as it arrives (service or command line): plan name (parsed by makePlan),
/// key=value arguments, and the per-cell heights of a `custom` plan.
struct PlanRequest {
  std::string plan;
  std::map<std::string, std::string> args;
  std::vector<double> heights_m;
};

class PosturePlan {
 public:
  virtual ~PosturePlan() = default;
  virtual PlanKind kind() const = 0;
  /// planKindName(kind()).
  std::string name() const { return planKindName(kind()); }
  /// Targets `elapsed_s` after the plan started.
  virtual PlanTargets targets(double elapsed_s) const = 0;
  /// Targets `elapsed_s` after the plan started, given what the cells sense now; called once
  /// per plan step, in time order. Plans that do not act on the cells' readings give targets().
  virtual PlanTargets sensedTargets(double elapsed_s, const SensedCells& sensed) {
    (void)sensed;
    return targets(elapsed_s);
  }
  /// The plan's parameters after defaults, as "key=value ...".
  virtual std::string describe() const = 0;
};

/// Builds a plan. On any problem (unknown plan, unknown or missing argument, non-numeric,
/// non-finite or out-of-range value, a turn beyond the limits or too fast, a custom plan with
/// the wrong number of heights) returns nullptr and says why in *error.
std::unique_ptr<PosturePlan> makePlan(const PlanRequest& request, const PlanConfig& config, const BedGrid& grid,
                                      const BodyFootprint& body, std::string* error);

/// The bed manager's own plans: every cell held at one height after a cell failed
/// ("safe_level": keeps the patient level), and manual per-cell heights ("custom", validated by
/// the caller against the cells' limits).
std::unique_ptr<PosturePlan> makeSafeLevelPlan(const BedGrid& grid, double height_m);
std::unique_ptr<PosturePlan> makeCustomPlan(std::vector<double> heights_m);

/// Weights w (per cell id) of the least-squares lateral slope dh/dy of the cells that carry the
/// trunk (rows body.first_row..last_row, columns within `support_half_width_m` of the body's
/// midline): sum w_i h_i is that slope, atan of it the roll the patient's trunk follows (what the
/// rate limiter bounds). Outer columns are left out: a turn clamps them at the height limits, so
/// a slope over the whole width would understate the tilt under the body.
std::vector<double> rollSlopeWeights(const BedGrid& grid, const BodyFootprint& body,
                                     double support_half_width_m = 0.25);

/// Longest number text a plan argument may be (a double needs far fewer characters).
constexpr std::size_t kMaxNumberChars = 64;
/// Parses a plan argument strictly: a decimal number filling the whole text (no hex, no
/// "inf"/"nan", no trailing characters, at most kMaxNumberChars). False when it is not one.
bool parseDecimal(const std::string& text, double* value);

/// Keys of PlanConfig for YAML and the parameter server ("plans/..." in the bed manager).
const ParamTable<PlanConfig>& planConfigFields();

/// The plans makePlan knows, with their arguments (for help texts).
const std::map<std::string, std::string>& planHelp();

}  // namespace nursing_bed
