#include "nursing_bed/core/bed/adaptive_support.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "nursing_bed/core/io/errors.h"

namespace nursing_bed {

Status AdaptiveSupportParams::validate(double min_height_m, double nominal_height_m, double max_height_m,
                                       const std::string& k) const {
  ErrorList e;
  auto finite = [](double v) { return std::isfinite(v); };
  const double span_m = max_height_m - min_height_m;
  e.addIf(!(finite(survey_s) && survey_s >= 0.0), k, "survey_s must be >= 0");
  e.addIf(!(finite(contact_load_n) && contact_load_n > 0.0), k, "contact_load_n must be positive");
  e.addIf(!(finite(head_length_m) && head_length_m >= 0.0), k, "head_length_m must be >= 0");
  e.addIf(!(finite(heel_zone_m) && heel_zone_m > 0.0), k, "heel_zone_m must be positive");
  e.addIf(!(finite(pelvis_length_m) && pelvis_length_m > 0.0), k, "pelvis_length_m must be positive");
  e.addIf(!(heel_height_m >= min_height_m && heel_height_m <= nominal_height_m), k,
          "heel_height_m must lie in [min_height_m, nominal_height_m]");
  e.addIf(!(finite(calf_length_m) && calf_length_m >= 0.0), k, "calf_length_m must be >= 0");
  e.addIf(!(calf_lift_m >= 0.0 && calf_lift_m <= span_m), k,
          "calf_lift_m must lie in [0, max_height_m - min_height_m]");
  e.addIf(!(finite(thigh_length_m) && thigh_length_m >= 0.0), k, "thigh_length_m must be >= 0");
  e.addIf(!(thigh_lift_m >= 0.0 && thigh_lift_m <= span_m), k,
          "thigh_lift_m must lie in [0, max_height_m - min_height_m]");
  e.addIf(!(margin_height_m >= min_height_m && margin_height_m <= nominal_height_m), k,
          "margin_height_m must lie in [min_height_m, nominal_height_m]");
  e.addIf(!(finite(level_gain_m_n_s) && level_gain_m_n_s >= 0.0 && level_gain_m_n_s <= 1e-3), k,
          "level_gain_m_n_s must lie in [0, 1e-3]");
  e.addIf(!(level_range_m >= 0.0 && level_range_m <= span_m), k,
          "level_range_m must lie in [0, max_height_m - min_height_m]");
  e.addIf(!(reach_m >= 0.0 && reach_m <= level_range_m), k, "reach_m must lie in [0, level_range_m]");
  e.addIf(!(finite(relief_budget_s) && relief_budget_s > relief_s), k, "relief_budget_s must exceed relief_s");
  e.addIf(!(finite(dose_limit) && dose_limit > 0.0), k, "dose_limit must be positive");
  e.addIf(!(finite(relief_s) && relief_s > 0.0), k, "relief_s must be positive");
  e.addIf(!(relief_drop_m >= 0.0 && relief_drop_m <= span_m), k,
          "relief_drop_m must lie in [0, max_height_m - min_height_m]");
  e.addIf(!(finite(max_rate_m_s) && max_rate_m_s > 0.0), k, "max_rate_m_s must be positive");
  e.addIf(!(finite(tolerance.reference_pressure_pa) && tolerance.reference_pressure_pa > 0.0 &&
            finite(tolerance.reference_time_s) && tolerance.reference_time_s > 0.0 && finite(tolerance.exponent) &&
            tolerance.exponent > 0.0 && finite(tolerance.floor_pressure_pa) && tolerance.floor_pressure_pa >= 0.0),
          k,
          "tolerance: reference_pressure_pa, reference_time_s and exponent must be positive, floor_pressure_pa >= 0");
  return e.status();
}

const ParamTable<AdaptiveSupportParams>& adaptiveSupportFields() {
  using P = AdaptiveSupportParams;
#define NB_FIELD(key, desc, expr) realField<P>(key, desc, [](P& p) -> double& { return expr; })
  static const ParamTable<P> fields = {
      NB_FIELD("survey_s", "the bed stays level this long before the load map is read [s]", p.survey_s),
      NB_FIELD("contact_load_n", "a cell sensing more than this above an empty cell is under the body [N]",
               p.contact_load_n),
      NB_FIELD("head_length_m", "loaded rows this close to the head end are the head [m]", p.head_length_m),
      NB_FIELD("heel_zone_m", "loaded leg rows this close to the foot end are the heels [m]", p.heel_zone_m),
      NB_FIELD("pelvis_length_m", "the last trunk rows over this length are the pelvis [m]", p.pelvis_length_m),
      NB_FIELD("heel_height_m", "floated heel cells' height [m]", p.heel_height_m),
      NB_FIELD("calf_length_m", "the leg rows over this length before the heels are the calves [m]", p.calf_length_m),
      NB_FIELD("calf_lift_m", "the calves' cells go this much higher so the feet hang clear [m]", p.calf_lift_m),
      NB_FIELD("thigh_length_m", "the leg rows over this length after the pelvis are the thighs [m]", p.thigh_length_m),
      NB_FIELD("thigh_lift_m", "the thighs' cells go this much higher, off-loading the pelvis [m]", p.thigh_lift_m),
      NB_FIELD("margin_height_m", "lowest height of a cell under the trunk or pelvis [m]", p.margin_height_m),
      NB_FIELD("level_gain_m_n_s", "levelling: height change per N of excess load per s [m/(N s)]", p.level_gain_m_n_s),
      NB_FIELD("level_range_m", "levelling moves a cell at most this far from nominal [m]", p.level_range_m),
      NB_FIELD("reach_m", "levelling raises a cell not under the body at most this far above nominal [m]", p.reach_m),
      NB_FIELD("relief_budget_s", "a region is relieved after this long under load [s]", p.relief_budget_s),
      NB_FIELD("dose_limit", "or sooner, when its sensed dose reaches this [-]", p.dose_limit),
      NB_FIELD("relief_s", "a relief lasts this long [s]", p.relief_s),
      NB_FIELD("relief_drop_m", "relieved cells go this much lower, their neighbour rows higher [m]", p.relief_drop_m),
      NB_FIELD("max_rate_m_s", "fastest change of a target [m/s]", p.max_rate_m_s),
      NB_FIELD("tolerance/reference_pressure_pa", "a point of the tolerance curve: this pressure ... [Pa]",
               p.tolerance.reference_pressure_pa),
      NB_FIELD("tolerance/reference_time_s", "... is borne this long [s]", p.tolerance.reference_time_s),
      NB_FIELD("tolerance/exponent", "allowed time ~ pressure^-exponent [-]", p.tolerance.exponent),
      NB_FIELD("tolerance/floor_pressure_pa", "no dose at or below this pressure [Pa]", p.tolerance.floor_pressure_pa),
  };
#undef NB_FIELD
  return fields;
}

namespace {

/// How many rows of `pitch_m` cover `length_m` (at least one).
int rowsWithin(double length_m, double pitch_m) {
  return std::max(1, static_cast<int>(std::ceil(length_m / pitch_m - 1e-9)));
}

}  // namespace

std::vector<double> sensedLoads(const BedGrid& grid, const SensedCells& sensed) {
  std::vector<double> loads(grid.cells(), 0.0);
  for (int i = 0; i < grid.cells(); ++i) {
    const double l = i < static_cast<int>(sensed.load_n.size()) ? sensed.load_n[i] : NAN;
    const double p = i < static_cast<int>(sensed.gauge_pressure_pa.size()) ? sensed.gauge_pressure_pa[i] : NAN;
    if (std::isfinite(l)) loads[i] = std::max(0.0, l);
    else if (std::isfinite(p)) loads[i] = std::max(0.0, p * grid.cellAreaM2());
  }
  return loads;
}

double emptyCellLoad(const std::vector<double>& loads_n) {
  if (loads_n.empty()) return 0.0;
  std::vector<double> sorted = loads_n;
  const std::size_t k = sorted.size() / 10;
  std::nth_element(sorted.begin(), sorted.begin() + k, sorted.end());
  return std::max(0.0, sorted[k]);
}

namespace {

/// The columns of `rows` from the first to the last loaded one, widened by one either side
/// and kept on the bed; empty when no cell of them is loaded.
std::pair<int, int> loadedColumnSpan(const BedGrid& grid, const std::vector<double>& loads,
                                     const std::vector<int>& rows, double contact_load_n) {
  int lo = grid.cols, hi = -1;
  for (int r : rows)
    for (int c = 0; c < grid.cols; ++c)
      if (loads[grid.id(r, c)] > contact_load_n) lo = std::min(lo, c), hi = std::max(hi, c);
  if (hi < 0) return {0, -1};
  return {std::max(0, lo - 1), std::min(grid.cols - 1, hi + 1)};
}

/// Heel rows and cells: the loaded rows within the heel zone of the body's foot end, and every
/// cell from there to the bed's foot end one column either side of the feet, so that no cover
/// slope up to a cell left high reaches a heel. The calves: the leg rows within calf_length_m
/// before the heel rows, the same columns.
void findHeels(const BedGrid& grid, const std::vector<double>& loads, const AdaptiveSupportParams& params,
               int first_leg_row, BodyLayout* out) {
  for (int h = std::max(first_leg_row, out->first_row); h <= out->last_row; ++h)
    if ((out->last_row - h) * grid.pitch_m < params.heel_zone_m) out->heel_rows.push_back(h);
  if (out->heel_rows.empty()) return;
  const auto [lo, hi] = loadedColumnSpan(grid, loads, out->heel_rows, params.contact_load_n);
  const int first_calf =
      std::max(first_leg_row, out->heel_rows.front() - rowsWithin(params.calf_length_m, grid.pitch_m));
  for (int h = params.calf_length_m > 0.0 ? first_calf : out->heel_rows.front(); h < grid.rows; ++h)
    for (int c = lo; c <= hi; ++c)
      (h < out->heel_rows.front() ? out->calf_cells : out->heel_cells).push_back(grid.id(h, c));
}

/// The thighs: the leg rows within thigh_length_m after the trunk (from `first_leg_row`), up
/// to the calves or heels, their loaded columns and one either side.
void findThighs(const BedGrid& grid, const std::vector<double>& loads, const AdaptiveSupportParams& params,
                int first_leg_row, BodyLayout* out) {
  if (!(params.thigh_length_m > 0.0)) return;
  int end = std::min(out->last_row + 1, first_leg_row + rowsWithin(params.thigh_length_m, grid.pitch_m));
  if (!out->calf_cells.empty()) end = std::min(end, grid.row(out->calf_cells.front()));
  if (!out->heel_rows.empty()) end = std::min(end, out->heel_rows.front());
  for (int r = first_leg_row; r < end; ++r) {
    const auto [lo, hi] = loadedColumnSpan(grid, loads, {r}, params.contact_load_n);
    for (int c = lo; c <= hi; ++c) out->thigh_cells.push_back(grid.id(r, c));
  }
}

}  // namespace

std::optional<BodyLayout> inferBodyLayout(const BedGrid& grid, const std::vector<double>& sensed_loads,
                                          const AdaptiveSupportParams& params) {
  BodyLayout out;
  out.empty_load_n = emptyCellLoad(sensed_loads);
  std::vector<double> loads(sensed_loads.size());
  for (std::size_t i = 0; i < loads.size(); ++i) loads[i] = std::max(0.0, sensed_loads[i] - out.empty_load_n);
  out.first_row = grid.rows;
  out.last_row = -1;
  double sum = 0.0, moment = 0.0;
  for (int r = 0; r < grid.rows; ++r)
    for (int c = 0; c < grid.cols; ++c) {
      const double l = loads.at(grid.id(r, c));
      if (!(l > params.contact_load_n)) continue;
      out.first_row = std::min(out.first_row, r);
      out.last_row = std::max(out.last_row, r);
      sum += l;
      moment += l * c;
    }
  if (out.last_row < 0) return std::nullopt;
  out.midline_col = static_cast<int>(std::lround(moment / sum));
  auto load = [&](int r, int c) { return loads[grid.id(r, c)]; };
  auto midlineCarries = [&](int r) {
    double row_max = 0.0;
    for (int c = 0; c < grid.cols; ++c) row_max = std::max(row_max, load(r, c));
    return row_max > params.contact_load_n && load(r, out.midline_col) >= row_max;
  };
  int r = out.first_row;
  for (; r <= out.last_row && (r - out.first_row) * grid.pitch_m < params.head_length_m; ++r)
    out.head_rows.push_back(r);
  for (; r <= out.last_row && midlineCarries(r); ++r) out.trunk_rows.push_back(r);
  if (out.trunk_rows.empty()) return std::nullopt;
  const int pelvis = std::min<int>(out.trunk_rows.size(), rowsWithin(params.pelvis_length_m, grid.pitch_m));
  out.pelvis_rows.assign(out.trunk_rows.end() - pelvis, out.trunk_rows.end());
  findHeels(grid, loads, params, r, &out);
  findThighs(grid, loads, params, r, &out);
  for (int t : out.trunk_rows) {
    const auto [lo, hi] = loadedColumnSpan(grid, loads, {t}, params.contact_load_n);
    for (int c = lo; c <= hi; ++c) out.trunk_cells.push_back(grid.id(t, c));
  }
  std::vector<bool> shaped(grid.cells(), false);
  for (const auto* cells : {&out.heel_cells, &out.calf_cells})
    for (std::uint32_t id : *cells) shaped[id] = true;
  for (int row = out.first_row; row <= out.last_row; ++row)
    for (int c = 0; c < grid.cols; ++c)
      if (!shaped[grid.id(row, c)]) out.level_cells.push_back(grid.id(row, c));
  return out;
}

AdaptiveSupport::AdaptiveSupport(const AdaptiveSupportParams& params, const BedGrid& grid, double min_height_m,
                                 double nominal_height_m, double max_height_m)
    : params_(params),
      grid_(grid),
      min_height_m_(min_height_m),
      nominal_height_m_(nominal_height_m),
      max_height_m_(max_height_m),
      offset_m_(grid.cells(), 0.0),
      heights_m_(grid.cells(), nominal_height_m) {}

void AdaptiveSupport::buildRegions() {
  // The pelvis first, the upper trunk and the head after it: the budgets start staggered so
  // that one region is relieved at a time, evenly spread over the budget.
  std::vector<int> upper;
  for (int r : layout_->trunk_rows)
    if (std::find(layout_->pelvis_rows.begin(), layout_->pelvis_rows.end(), r) == layout_->pelvis_rows.end())
      upper.push_back(r);
  regions_ = {{"pelvis", layout_->pelvis_rows}, {"upper trunk", upper}, {"head", layout_->head_rows}};
  regions_.erase(std::remove_if(regions_.begin(), regions_.end(), [](const Region& g) { return g.rows.empty(); }),
                 regions_.end());
  const double n = static_cast<double>(regions_.size());
  for (std::size_t k = 0; k < regions_.size(); ++k) regions_[k].loaded_s = params_.relief_budget_s * (n - 1 - k) / n;
}

void AdaptiveSupport::level(const std::vector<double>& loads, double dt_s) {
  // Each cell under the body moves towards its neighbourhood's mean load: an over-loaded cell
  // goes down, the under-loaded cells around it go up and take its load (negative feedback: a
  // raised cell takes more load), so the bed fills the body's hollows and envelops it.
  const std::vector<std::uint32_t>& cells = layout_->level_cells;
  std::vector<bool> in(grid_.cells(), false);
  for (std::uint32_t id : cells) in[id] = true;
  for (std::uint32_t id : cells) {
    double sum = 0.0;
    int n = 0;
    for (int r = std::max(0, grid_.row(id) - 1); r <= std::min(grid_.rows - 1, grid_.row(id) + 1); ++r)
      for (int c = std::max(0, grid_.col(id) - 1); c <= std::min(grid_.cols - 1, grid_.col(id) + 1); ++c)
        if (in[grid_.id(r, c)]) {
          sum += loads[grid_.id(r, c)];
          ++n;
        }
    const double step = params_.level_gain_m_n_s * (sum / n - loads[id]) * dt_s;
    const double top_m = loads[id] > params_.contact_load_n ? params_.level_range_m : params_.reach_m;
    offset_m_[id] = std::clamp(offset_m_[id] + step, -params_.level_range_m, std::max(top_m, offset_m_[id]));
  }
}

double AdaptiveSupport::regionPressurePa(const Region& region, const std::vector<double>& loads) const {
  double peak = 0.0;
  for (int r : region.rows)
    for (int c = 0; c < grid_.cols; ++c) peak = std::max(peak, loads[grid_.id(r, c)]);
  return peak / grid_.cellAreaM2();
}

void AdaptiveSupport::account(const std::vector<double>& loads, double elapsed_s, double dt_s) {
  if (relieving_ >= 0 && elapsed_s >= relief_end_s_) {
    regions_[relieving_].loaded_s = 0.0;  // reperfused: its budget and dose start again
    regions_[relieving_].dose = 0.0;
    relieving_ = -1;
  }
  int due = -1;
  double most_due = 1.0;
  for (std::size_t k = 0; k < regions_.size(); ++k) {
    Region& g = regions_[k];
    const double p = regionPressurePa(g, loads);
    if (p * grid_.cellAreaM2() > params_.contact_load_n && static_cast<int>(k) != relieving_) {
      g.loaded_s += dt_s;
      g.dose += dt_s / params_.tolerance.allowedTimeS(p);
    }
    const double dueness = std::max(g.loaded_s / params_.relief_budget_s, g.dose / params_.dose_limit);
    if (dueness >= most_due) {
      most_due = dueness;
      due = static_cast<int>(k);
    }
  }
  if (relieving_ < 0 && due >= 0) {
    relieving_ = due;
    relief_end_s_ = elapsed_s + params_.relief_s;
  }
}

std::vector<double> AdaptiveSupport::wanted() const {
  std::vector<double> h(grid_.cells());
  for (int i = 0; i < grid_.cells(); ++i) h[i] = nominal_height_m_ + offset_m_[i];
  for (std::uint32_t id : layout_->heel_cells) h[id] = params_.heel_height_m;
  for (std::uint32_t id : layout_->calf_cells) h[id] += params_.calf_lift_m;
  for (std::uint32_t id : layout_->thigh_cells) h[id] += params_.thigh_lift_m;
  if (relieving_ >= 0) {
    const std::vector<int>& rows = regions_[relieving_].rows;
    const std::vector<int>& pelvis = layout_->pelvis_rows;
    for (int r = rows.front() - 1; r <= rows.back() + 1; ++r) {
      if (r < 0 || r >= grid_.rows) continue;
      const bool inside = r >= rows.front() && r <= rows.back();
      // The relieved load goes to the neighbour rows, never onto the sacrum and trochanters.
      if (!inside && std::find(pelvis.begin(), pelvis.end(), r) != pelvis.end()) continue;
      for (int c = 0; c < grid_.cols; ++c) h[grid_.id(r, c)] += inside ? -params_.relief_drop_m : params_.relief_drop_m;
    }
  }
  // The bottoming-out margin under the trunk (pelvis and trochanters included) holds whatever
  // levelling or a relief wants.
  for (std::uint32_t id : layout_->trunk_cells) h[id] = std::max(h[id], params_.margin_height_m);
  for (double& v : h) v = std::clamp(v, min_height_m_, max_height_m_);
  return h;
}

std::vector<double> AdaptiveSupport::update(double elapsed_s, const SensedCells& sensed, std::string* phase) {
  const double dt_s = std::max(0.0, elapsed_s - last_elapsed_s_);
  last_elapsed_s_ = std::max(last_elapsed_s_, elapsed_s);
  std::vector<double> want(grid_.cells(), nominal_height_m_);
  std::vector<double> loads = sensedLoads(grid_, sensed);
  if (!layout_ && elapsed_s >= params_.survey_s) {
    layout_ = inferBodyLayout(grid_, loads, params_);
    if (layout_) buildRegions();
  }
  if (!layout_) {
    *phase = elapsed_s < params_.survey_s ? "surveying" : "level: no body sensed";
  } else {
    for (double& l : loads) l = std::max(0.0, l - layout_->empty_load_n);
    // Levelling waits while a region is relieved: the relief's load shift is not an imbalance
    // to level (the offsets would wind up and over-load the region when it comes back).
    if (relieving_ < 0) level(loads, dt_s);
    account(loads, elapsed_s, dt_s);
    want = wanted();
    *phase = relieving_ >= 0 ? "relieving " + regions_[relieving_].name : "adapting";
  }
  const double step = params_.max_rate_m_s * dt_s;
  for (int i = 0; i < grid_.cells(); ++i) heights_m_[i] += std::clamp(want[i] - heights_m_[i], -step, step);
  return heights_m_;
}

}  // namespace nursing_bed
