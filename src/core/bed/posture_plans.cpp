#include "nursing_bed/core/bed/posture_plans.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <set>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/io/errors.h"
#include "nursing_bed/core/io/number_text.h"
#include "nursing_bed/core/physics/units.h"

namespace nursing_bed {

Status PlanConfig::validate() const {
  ErrorList errors;
  errors.addIf(!(min_height_m >= 0.0 && max_height_m > min_height_m), "need 0 <= min_height_m < max_height_m");
  errors.addIf(!(nominal_height_m >= min_height_m && nominal_height_m <= max_height_m),
               "nominal_height_m must lie in [min_height_m, max_height_m]");
  errors.addIf(!(max_tilt_deg > 0.0 && max_tilt_deg <= kHardMaxTiltDeg), "max_tilt_deg must lie in (0, 40]");
  errors.addIf(!(max_tilt_rate_deg_s > 0.0), "max_tilt_rate_deg_s must be positive");
  errors.addIf(!(bed_tilt_rate_fraction > 0.0 && bed_tilt_rate_fraction <= 1.0),
               "bed_tilt_rate_fraction must lie in (0, 1]");
  errors.addIf(!(turn_ramp_s > 0.0 && turn_dwell_s >= 0.0), "turn_ramp_s must be positive, turn_dwell_s >= 0");
  errors.addIf(!(alternating_low_m >= min_height_m && alternating_high_m <= max_height_m &&
                 alternating_low_m < alternating_high_m),
               "alternating heights must satisfy min <= low < high <= max");
  errors.addIf(!(alternating_transition_s > 0.0), "alternating_transition_s must be positive");
  errors.addIf(!(alternating_period_s >= 6.0 * alternating_transition_s),
               "alternating_period_s too short for the transition");
  errors.addIf(static_head_rows < 0, "static_head_rows must be >= 0");
  errors.addIf(!(max_inflate_timeout_s > 0.0), "max_inflate_timeout_s must be positive");
  errors.addNested(adaptive.validate(min_height_m, nominal_height_m, max_height_m, "adaptive/"));
  return errors.status();
}

namespace {

// Reads plan arguments, each at most once, with the reasons for refusal in one place.
class Args {
 public:
  Args(const std::map<std::string, std::string>& args, const std::string& plan) : args_(args), plan_(plan) {}

  double number(const std::string& key, double fallback, double lo, double hi, bool required = false) {
    used_.insert(key);
    const auto it = args_.find(key);
    if (it == args_.end()) {
      if (required) fail("needs " + key);
      return fallback;
    }
    double v = 0.0;
    if (it->second.size() > kMaxNumberChars)
      fail(key + " must be a number of at most " + std::to_string(kMaxNumberChars) + " characters, got " +
           std::to_string(it->second.size()));
    if (!parseDecimal(it->second, &v)) {
      const std::string lower = lowered(it->second);
      if (lower.find("nan") != std::string::npos || lower.find("inf") != std::string::npos ||
          std::isinf(std::strtod(it->second.c_str(), nullptr)))
        fail(key + " must be finite");
      fail(key + " must be a number (decimal digits only), got '" + it->second + "'");
    }
    if (v < lo || v > hi) {
      std::ostringstream m;
      m << key << " = " << v << " is outside [" << lo << ", " << hi << "]";
      fail(m.str());
    }
    return v;
  }

  std::string word(const std::string& key, const std::vector<std::string>& allowed, const std::string& fallback,
                   bool required = false) {
    used_.insert(key);
    const auto it = args_.find(key);
    if (it == args_.end()) {
      if (required) fail("needs " + key + " (" + join(allowed) + ")");
      return fallback;
    }
    if (std::find(allowed.begin(), allowed.end(), it->second) == allowed.end())
      fail(key + " must be one of " + join(allowed) + ", got '" + it->second + "'");
    return it->second;
  }

  /// Refuses arguments the plan does not take.
  void finish() const {
    for (const auto& a : args_)
      if (!used_.count(a.first)) fail("does not take '" + a.first + "'");
  }

  bool has(const std::string& key) const { return args_.count(key) != 0; }

  [[noreturn]] void fail(const std::string& what) const { throw std::invalid_argument(plan_ + ": " + what); }

 private:
  static std::string lowered(std::string s) {
    for (char& ch : s) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    return s;
  }
  static std::string join(const std::vector<std::string>& v) {
    std::string s;
    for (const auto& w : v) s += (s.empty() ? "" : "|") + w;
    return s;
  }
  const std::map<std::string, std::string>& args_;
  std::string plan_;
  std::set<std::string> used_;
};

std::string fmt(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

class UniformPlan : public PosturePlan {
 public:
  UniformPlan(PlanKind kind, const BedGrid& grid, double height_m, double timeout_s)
      : kind_(kind), cells_(grid.cells()), height_m_(height_m), timeout_s_(timeout_s) {}
  PlanKind kind() const override { return kind_; }
  PlanTargets targets(double elapsed_s) const override {
    PlanTargets t;
    t.heights_m.assign(cells_, height_m_);
    t.phase = timeout_s_ > 0.0 ? (elapsed_s < timeout_s_ ? "inflated" : "timed out") : "holding";
    t.finished = timeout_s_ > 0.0 && elapsed_s >= timeout_s_;
    return t;
  }
  std::string describe() const override {
    return "height_m=" + fmt(height_m_) + (timeout_s_ > 0.0 ? " timeout_s=" + fmt(timeout_s_) : "");
  }

 private:
  PlanKind kind_;
  int cells_;
  double height_m_, timeout_s_;
};

class CprPlan : public PosturePlan {
 public:
  PlanKind kind() const override { return PlanKind::kCpr; }
  PlanTargets targets(double) const override {
    PlanTargets t;
    t.vent_all = true;
    t.phase = "venting";
    return t;
  }
  std::string describe() const override { return ""; }
};

class CustomPlan : public PosturePlan {
 public:
  explicit CustomPlan(std::vector<double> heights) : heights_(std::move(heights)) {}
  PlanKind kind() const override { return PlanKind::kCustom; }
  PlanTargets targets(double) const override {
    PlanTargets t;
    t.heights_m = heights_;
    t.phase = "holding";
    return t;
  }
  std::string describe() const override { return std::to_string(heights_.size()) + " heights"; }

 private:
  std::vector<double> heights_;
};

/// A lateral turn towards `direction` (+1: the patient's left) to `angle_deg`, reached over `ramp_s`.
struct TurnRequest {
  double direction = 1.0, angle_deg = 0.0, ramp_s = 0.0;
};

/// The height of a cell in column `col` under the body at turn angle `a_deg` (signed, + lowers
/// the patient's left) of a turn to `full_deg`: a plane tilted across the bed about the body's
/// midline, blended from the flat height into it as the angle grows so that a turn's start and
/// end are continuous. Not clamped.
double tiltedHeight(const PlanConfig& c, const BedGrid& g, const BodyFootprint& b, int col, double a_deg,
                    double full_deg) {
  const double slope = -std::tan(a_deg * kPi / 180.0);
  const double mid = 0.5 * (c.min_height_m + c.max_height_m);
  const double w = std::min(1.0, std::fabs(a_deg) / std::max(full_deg, 1e-9));
  return c.nominal_height_m + w * (mid - c.nominal_height_m) + slope * (g.y(col) - b.center_y_m);
}

// Lateral turn: the cells under the body form a plane tilted across the bed about the body's
// midline; the body rolls with it. Ramp (rate-limited), dwell, and optionally back to flat.
class LateralTurnPlan : public PosturePlan {
 public:
  LateralTurnPlan(const PlanConfig& c, const BedGrid& g, const BodyFootprint& b, double direction, double angle_deg,
                  double ramp_s, double dwell_s, bool back)
      : config_(c),
        grid_(g),
        body_(b),
        direction_(direction),
        angle_deg_(angle_deg),
        ramp_s_(ramp_s),
        dwell_s_(dwell_s),
        back_(back) {}
  PlanKind kind() const override { return PlanKind::kLateralTurn; }
  PlanTargets targets(double t) const override {
    PlanTargets out;
    double a = angle_deg_;
    if (t < ramp_s_) {
      a = angle_deg_ * t / ramp_s_;
      out.phase = "ramp";
    } else if (!back_ || t < ramp_s_ + dwell_s_) {
      out.phase = "dwell";
    } else if (t < 2.0 * ramp_s_ + dwell_s_) {
      a = angle_deg_ * (1.0 - (t - ramp_s_ - dwell_s_) / ramp_s_);
      out.phase = "return";
    } else {
      a = 0.0;
      out.phase = "flat";
      out.finished = true;
    }
    // Turning towards the patient's left (+) lowers the left (+y) side.
    out.tilt_deg = direction_ * a;
    out.heights_m.assign(grid_.cells(), config_.nominal_height_m);
    for (int r = std::max(0, body_.first_row); r <= std::min(grid_.rows - 1, body_.last_row); ++r)
      for (int c = 0; c < grid_.cols; ++c)
        out.heights_m[grid_.id(r, c)] = std::clamp(tiltedHeight(config_, grid_, body_, c, out.tilt_deg, angle_deg_),
                                                   config_.min_height_m, config_.max_height_m);
    return out;
  }
  std::string describe() const override {
    return std::string("side=") + (direction_ > 0 ? "left" : "right") + " angle_deg=" + fmt(angle_deg_) +
           " ramp_s=" + fmt(ramp_s_) + " dwell_s=" + fmt(dwell_s_) + " return=" + (back_ ? "yes" : "no");
  }

 private:
  PlanConfig config_;
  BedGrid grid_;
  BodyFootprint body_;
  double direction_, angle_deg_, ramp_s_, dwell_s_;
  bool back_;
};

// Alternating pressure: rows beyond the static head rows form N groups (row mod N); in each
// N-th of the period one group is low. The next group lowers only `transition_s` after the
// previous one was sent back up, so two adjacent rows are never low together.
class AlternatingPlan : public PosturePlan {
 public:
  AlternatingPlan(const PlanConfig& c, const BedGrid& g, int groups, double period_s, double low_m, double high_m,
                  int head_rows)
      : config_(c),
        grid_(g),
        groups_(groups),
        period_s_(period_s),
        low_m_(low_m),
        high_m_(high_m),
        head_rows_(head_rows) {}
  PlanKind kind() const override { return PlanKind::kAlternating; }
  PlanTargets targets(double t) const override {
    PlanTargets out;
    const double slot = period_s_ / groups_;
    const long index = static_cast<long>(std::floor(t / slot));
    const int low_group = static_cast<int>(index % groups_);
    const bool lowering = t - index * slot >= config_.alternating_transition_s;
    out.phase = lowering ? "group " + std::to_string(low_group + 1) + " of " + std::to_string(groups_) + " low"
                         : "all up before group " + std::to_string(low_group + 1);
    out.heights_m.assign(grid_.cells(), high_m_);
    for (int r = 0; r < grid_.rows; ++r) {
      for (int c = 0; c < grid_.cols; ++c) {
        double h = high_m_;
        if (r < head_rows_) h = config_.nominal_height_m;
        else if (lowering && (r - head_rows_) % groups_ == low_group) h = low_m_;
        out.heights_m[grid_.id(r, c)] = h;
      }
    }
    return out;
  }
  std::string describe() const override {
    return "pattern=1in" + std::to_string(groups_) + " period_s=" + fmt(period_s_) + " low_m=" + fmt(low_m_) +
           " high_m=" + fmt(high_m_) + " static_head_rows=" + std::to_string(head_rows_);
  }

 private:
  PlanConfig config_;
  BedGrid grid_;
  int groups_;
  double period_s_, low_m_, high_m_;
  int head_rows_;
};

// Adaptive support: the cells' heights from what they sense (AdaptiveSupport holds the policy
// and its state, which the sensed readings advance). With a turn, the turn's tilt plane starts
// once the survey has read the body on the level bed and ramps in; the adaptive offsets from
// the flat height (heels, calves, thighs, levelling, relief) ride on it.
class AdaptivePlan : public PosturePlan {
 public:
  AdaptivePlan(const PlanConfig& c, const BedGrid& g, const BodyFootprint& b, const AdaptiveSupportParams& p,
               std::optional<TurnRequest> turn)
      : config_(c),
        grid_(g),
        body_(b),
        turn_(turn),
        support_(p, g, c.min_height_m, c.nominal_height_m, c.max_height_m) {}
  PlanKind kind() const override { return PlanKind::kAdaptive; }
  PlanTargets targets(double elapsed_s) const override {
    PlanTargets t;
    t.heights_m = support_.targets();
    t.phase = phase_;
    if (!turn_) return t;
    const double turned_s = elapsed_s - support_.params().survey_s;
    const double a = turned_s <= 0.0 ? 0.0 : turn_->angle_deg * std::min(1.0, turned_s / turn_->ramp_s);
    t.tilt_deg = turn_->direction * a;
    for (int r = std::max(0, body_.first_row); r <= std::min(grid_.rows - 1, body_.last_row); ++r)
      for (int c = 0; c < grid_.cols; ++c) {
        double& h = t.heights_m[grid_.id(r, c)];
        h += tiltedHeight(config_, grid_, body_, c, t.tilt_deg, turn_->angle_deg) - config_.nominal_height_m;
        h = std::clamp(h, config_.min_height_m, config_.max_height_m);
      }
    if (a > 0.0) t.phase += a < turn_->angle_deg ? ", turning" : ", turned";
    return t;
  }
  PlanTargets sensedTargets(double elapsed_s, const SensedCells& sensed) override {
    support_.update(elapsed_s, sensed, &phase_);
    return targets(elapsed_s);
  }
  std::string describe() const override {
    const AdaptiveSupportParams& p = support_.params();
    std::string d = "heel_height_m=" + fmt(p.heel_height_m) + " margin_height_m=" + fmt(p.margin_height_m) +
                    " level_range_m=" + fmt(p.level_range_m) + " relief_budget_s=" + fmt(p.relief_budget_s) +
                    " relief_s=" + fmt(p.relief_s) + " dose_limit=" + fmt(p.dose_limit);
    if (turn_)
      d += std::string(" side=") + (turn_->direction > 0 ? "left" : "right") + " angle_deg=" + fmt(turn_->angle_deg) +
           " ramp_s=" + fmt(turn_->ramp_s);
    return d;
  }

 private:
  PlanConfig config_;
  BedGrid grid_;
  BodyFootprint body_;
  std::optional<TurnRequest> turn_;
  AdaptiveSupport support_;
  std::string phase_ = "surveying";
};

}  // namespace

bool parseDecimal(const std::string& text, double* value) {
  // Longer than any double needs is refused before parsing: a huge argument must not cost time.
  return !text.empty() && text.size() <= kMaxNumberChars && parseFiniteNumber(text, value);
}

std::vector<double> rollSlopeWeights(const BedGrid& grid, const BodyFootprint& body, double support_half_width_m) {
  std::vector<double> w(grid.cells(), 0.0);
  const int first = std::max(0, body.first_row), last = std::min(grid.rows - 1, body.last_row);
  std::vector<int> cols;
  for (int c = 0; c < grid.cols; ++c)
    if (std::fabs(grid.y(c) - body.center_y_m) <= support_half_width_m + 1e-9) cols.push_back(c);
  if (cols.size() < 2 || last < first) return w;
  double mean_y = 0.0, syy = 0.0;
  for (int c : cols) mean_y += grid.y(c) / cols.size();
  for (int c : cols) syy += (grid.y(c) - mean_y) * (grid.y(c) - mean_y);
  const int rows = last - first + 1;
  for (int r = first; r <= last; ++r)
    for (int c : cols) w[grid.id(r, c)] = (grid.y(c) - mean_y) / (syy * rows);
  return w;
}

std::unique_ptr<PosturePlan> makeSafeLevelPlan(const BedGrid& grid, double height_m) {
  return std::make_unique<UniformPlan>(PlanKind::kSafeLevel, grid, height_m, 0.0);
}

std::unique_ptr<PosturePlan> makeCustomPlan(std::vector<double> heights_m) {
  return std::make_unique<CustomPlan>(std::move(heights_m));
}

const ParamTable<PlanConfig>& planConfigFields() {
  using P = PlanConfig;
#define NB_FIELD(key, desc, expr) realField<P>(key, desc, [](P& p) -> double& { return expr; })
  static const ParamTable<P> fields = {
      NB_FIELD("nominal_height_m", "flat bed height [m]", p.nominal_height_m),
      NB_FIELD("min_height_m", "lowest height a plan commands [m]", p.min_height_m),
      NB_FIELD("max_height_m", "highest height a plan commands [m]", p.max_height_m),
      NB_FIELD("max_tilt_deg", "configured maximum lateral turn (hard cap 40) [deg]", p.max_tilt_deg),
      NB_FIELD("max_tilt_rate_deg_s", "fastest change of the turn angle [deg/s]", p.max_tilt_rate_deg_s),
      NB_FIELD("bed_tilt_rate_fraction",
               "fraction of max_tilt_rate_deg_s the bed's slope under the trunk changes at [-]",
               p.bed_tilt_rate_fraction),
      NB_FIELD("turn_ramp_s", "default ramp time of a turn [s]", p.turn_ramp_s),
      NB_FIELD("turn_dwell_s", "default dwell at the turned angle [s]", p.turn_dwell_s),
      NB_FIELD("alternating_period_s", "default alternating cycle [s]", p.alternating_period_s),
      NB_FIELD("alternating_low_m", "default height of the relieved cells [m]", p.alternating_low_m),
      NB_FIELD("alternating_high_m", "default height of the supporting cells [m]", p.alternating_high_m),
      NB_FIELD("alternating_transition_s", "time the rising group gets before the next one lowers [s]",
               p.alternating_transition_s),
      integerField<P>("static_head_rows", "head rows that alternating leaves at the nominal height [-]",
                      [](P& p) -> int& { return p.static_head_rows; }),
      NB_FIELD("max_inflate_timeout_s", "default time before max_inflate reverts [s]", p.max_inflate_timeout_s),
  };
#undef NB_FIELD
  static const ParamTable<P> with_adaptive = [] {
    ParamTable<P> t = fields;
    appendNested(&t, adaptiveSupportFields(), "adaptive/", [](P& p) -> AdaptiveSupportParams& { return p.adaptive; });
    return t;
  }();
  return with_adaptive;
}

const std::map<std::string, std::string>& planHelp() {
  static const std::map<std::string, std::string> help = {
      {planKindName(PlanKind::kFlat), "[height_m=H]"},
      {planKindName(PlanKind::kLateralTurn), "side=left|right angle_deg=A [ramp_s=S] [dwell_s=S] [return=yes|no]"},
      {planKindName(PlanKind::kAlternating),
       "pattern=1in2|1in3 [period_s=S] [low_m=H] [high_m=H] [static_head_rows=N]"},
      {planKindName(PlanKind::kMaxInflate), "[timeout_s=S]"},
      {planKindName(PlanKind::kCpr), "(no arguments)"},
      {planKindName(PlanKind::kCustom), "heights_m = one height per cell, by cell id"},
      {planKindName(PlanKind::kAdaptive),
       "[heel_height_m=H] [margin_height_m=H] [level_range_m=M] [relief_budget_s=S] [relief_s=S] [dose_limit=D] "
       "(any key of plans/adaptive/ without '/') [side=left|right angle_deg=A [ramp_s=S]]"},
  };
  return help;
}

namespace {

std::unique_ptr<PosturePlan> makeCustom(const PlanRequest& req, const PlanConfig& config, const BedGrid& grid,
                                        Args& args) {
  const double lo = config.min_height_m, hi = config.max_height_m;
  if (static_cast<int>(req.heights_m.size()) != grid.cells())
    args.fail("needs " + std::to_string(grid.cells()) + " heights (one per cell), got " +
              std::to_string(req.heights_m.size()));
  for (std::size_t i = 0; i < req.heights_m.size(); ++i) {
    const double h = req.heights_m[i];
    if (!std::isfinite(h) || h < lo || h > hi) {
      std::ostringstream m;
      m << "height " << h << " m of cell " << i << " is outside [" << lo << ", " << hi << "] m or not finite";
      args.fail(m.str());
    }
  }
  return std::make_unique<CustomPlan>(req.heights_m);
}

/// A turn's side, angle and ramp, checked against the configured angle and rate.
TurnRequest turnArguments(const PlanConfig& config, Args& args) {
  const std::string side = args.word("side", {"left", "right"}, "", true);
  const double angle = args.number("angle_deg", 0.0, 0.0, kHardMaxTiltDeg, true);
  if (angle > config.max_tilt_deg) {
    std::ostringstream m;
    m << "angle_deg = " << angle << " exceeds the configured maximum " << config.max_tilt_deg << " deg";
    args.fail(m.str());
  }
  if (!(angle > 0.0)) args.fail("angle_deg must be positive");
  const double min_ramp = angle / config.max_tilt_rate_deg_s;
  const double ramp = args.number("ramp_s", std::max(config.turn_ramp_s, min_ramp), 0.0, 3600.0);
  if (ramp < min_ramp) {
    std::ostringstream m;
    m << "ramp_s = " << ramp << " turns faster than " << config.max_tilt_rate_deg_s << " deg/s (at least " << min_ramp
      << " s for " << angle << " deg)";
    args.fail(m.str());
  }
  return {side == "left" ? 1.0 : -1.0, angle, ramp};
}

std::unique_ptr<PosturePlan> makeLateralTurn(const PlanConfig& config, const BedGrid& grid, const BodyFootprint& body,
                                             Args& args) {
  const TurnRequest turn = turnArguments(config, args);
  const double dwell = args.number("dwell_s", config.turn_dwell_s, 0.0, 7200.0);
  const bool back = args.word("return", {"yes", "no"}, "yes") == "yes";
  return std::make_unique<LateralTurnPlan>(config, grid, body, turn.direction, turn.angle_deg, turn.ramp_s, dwell,
                                           back);
}

std::unique_ptr<PosturePlan> makeAlternating(const PlanConfig& config, const BedGrid& grid, Args& args) {
  const double lo = config.min_height_m, hi = config.max_height_m;
  const std::string pattern = args.word("pattern", {"1in2", "1in3"}, "", true);
  const int groups = pattern == "1in2" ? 2 : 3;
  const double period =
      args.number("period_s", config.alternating_period_s, 2.0 * groups * config.alternating_transition_s, 7200.0);
  const double low = args.number("low_m", config.alternating_low_m, lo, hi);
  const double high = args.number("high_m", config.alternating_high_m, lo, hi);
  if (!(low < high)) args.fail("low_m must be below high_m");
  const double head = args.number("static_head_rows", config.static_head_rows, 0.0, grid.rows - groups);
  if (head != std::floor(head)) args.fail("static_head_rows must be a whole number");
  return std::make_unique<AlternatingPlan>(config, grid, groups, period, low, high, static_cast<int>(head));
}

// Any plans/adaptive/ key without a '/' may be given as an argument; the whole set is then
// validated as the configuration is. With `side` it is combined with a lateral turn (side,
// angle_deg, ramp_s as lateral_turn's).
std::unique_ptr<PosturePlan> makeAdaptive(const PlanConfig& config, const BedGrid& grid, const BodyFootprint& body,
                                          Args& args) {
  std::optional<TurnRequest> turn;
  if (args.has("side")) turn = turnArguments(config, args);
  AdaptiveSupportParams p = config.adaptive;
  for (const auto& field : adaptiveSupportFields()) {
    if (field.key.find('/') != std::string::npos) continue;
    field.set(p, args.number(field.key, field.get(p), -1e9, 1e9));
  }
  const Status valid = p.validate(config.min_height_m, config.nominal_height_m, config.max_height_m);
  if (!valid.ok()) args.fail(valid.message());
  return std::make_unique<AdaptivePlan>(config, grid, body, p, turn);
}

// The kind a request names, when it is one makePlan builds (safe_level is the manager's own).
PlanKind requestedKind(const std::string& name) {
  const std::optional<PlanKind> kind = planKindFromName(name);
  if (!kind || *kind == PlanKind::kSafeLevel) {
    std::string known;
    for (const auto& p : planHelp()) known += (known.empty() ? "" : ", ") + p.first;
    throw std::invalid_argument("unknown plan '" + name + "' (known: " + known + ")");
  }
  return *kind;
}

}  // namespace

std::string planKindName(PlanKind kind) {
  switch (kind) {
    case PlanKind::kFlat: return "flat";
    case PlanKind::kLateralTurn: return "lateral_turn";
    case PlanKind::kAlternating: return "alternating";
    case PlanKind::kMaxInflate: return "max_inflate";
    case PlanKind::kCpr: return "cpr";
    case PlanKind::kCustom: return "custom";
    case PlanKind::kSafeLevel: return "safe_level";
    case PlanKind::kAdaptive: return "adaptive";
  }
  return "";
}

std::optional<PlanKind> planKindFromName(const std::string& name) {
  for (PlanKind k : {PlanKind::kFlat, PlanKind::kLateralTurn, PlanKind::kAlternating, PlanKind::kMaxInflate,
                     PlanKind::kCpr, PlanKind::kCustom, PlanKind::kSafeLevel, PlanKind::kAdaptive})
    if (planKindName(k) == name) return k;
  return std::nullopt;
}

std::unique_ptr<PosturePlan> makePlan(const PlanRequest& req, const PlanConfig& config, const BedGrid& grid,
                                      const BodyFootprint& body, std::string* error) {
  try {
    const PlanKind kind = requestedKind(req.plan);
    if (kind != PlanKind::kCustom && !req.heights_m.empty())
      throw std::invalid_argument(req.plan + ": does not take per-cell heights");
    Args args(req.args, req.plan);
    std::unique_ptr<PosturePlan> plan;
    switch (kind) {
      case PlanKind::kFlat:
        plan = std::make_unique<UniformPlan>(
            kind, grid, args.number("height_m", config.nominal_height_m, config.min_height_m, config.max_height_m),
            0.0);
        break;
      case PlanKind::kMaxInflate:
        plan = std::make_unique<UniformPlan>(kind, grid, config.max_height_m,
                                             args.number("timeout_s", config.max_inflate_timeout_s, 1.0, 7200.0));
        break;
      case PlanKind::kCpr: plan = std::make_unique<CprPlan>(); break;
      case PlanKind::kCustom: plan = makeCustom(req, config, grid, args); break;
      case PlanKind::kLateralTurn: plan = makeLateralTurn(config, grid, body, args); break;
      case PlanKind::kAlternating: plan = makeAlternating(config, grid, args); break;
      case PlanKind::kAdaptive: plan = makeAdaptive(config, grid, body, args); break;
      case PlanKind::kSafeLevel: break;  // refused by requestedKind
    }
    args.finish();
    return plan;
  } catch (const std::invalid_argument& e) {
    if (error) *error = e.what();
    return nullptr;
  }
}

}  // namespace nursing_bed
