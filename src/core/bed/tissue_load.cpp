#include "nursing_bed/core/bed/tissue_load.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "nursing_bed/core/io/errors.h"

namespace nursing_bed {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::vector<int> segmentsNamed(std::initializer_list<const char*> names) {
  std::vector<int> out;
  for (const char* n : names) out.push_back(BodyModel::segmentIndex(n));
  return out;
}

// Windows along the body are fractions of stature from the vertex (segment table, body_model.cpp):
// the elbow joint at 0.368 H, +-0.05 H over the upper arm and the forearm. Across the pelvis the
// middle half is the sacrum, the outer quarters on each side the greater trochanters (they bear
// the load when the pelvis rolls).
std::vector<TissueRegion> makeDefaultRegions() {
  return {
      {"occiput", segmentsNamed({"head_neck"}), 0.0, 1.0, -1.0, 1.0},
      {"scapulae", segmentsNamed({"thorax"}), 0.0, 1.0, -1.0, 1.0},
      {"sacrum", segmentsNamed({"pelvis"}), 0.0, 1.0, -0.5, 0.5},
      {"right_trochanter", segmentsNamed({"pelvis"}), 0.0, 1.0, -1.0, -0.5},
      {"left_trochanter", segmentsNamed({"pelvis"}), 0.0, 1.0, 0.5, 1.0},
      {"right_elbow", segmentsNamed({"right_upper_arm", "right_forearm"}), 0.318, 0.418, -1.0, 1.0},
      {"left_elbow", segmentsNamed({"left_upper_arm", "left_forearm"}), 0.318, 0.418, -1.0, 1.0},
      {"right_heel", segmentsNamed({"right_foot"}), 0.0, 1.0, -1.0, 1.0},
      {"left_heel", segmentsNamed({"left_foot"}), 0.0, 1.0, -1.0, 1.0},
  };
}

using P = TissueLoadParams;
#define NB_FIELD(key, desc, expr) realField<P>(key, desc, [](P& p) -> double& { return expr; })

ParamTable<P> makeFields() {
  return {
      NB_FIELD("threshold_pa", "a region is above the threshold while its peak exceeds this [Pa]", p.threshold_pa),
      NB_FIELD("tolerance/reference_pressure_pa", "a point of the tolerance curve: this pressure ... [Pa]",
               p.tolerance.reference_pressure_pa),
      NB_FIELD("tolerance/reference_time_s", "... is borne this long [s]", p.tolerance.reference_time_s),
      NB_FIELD("tolerance/exponent", "allowed time ~ pressure^-exponent [-]", p.tolerance.exponent),
      NB_FIELD("tolerance/floor_pressure_pa", "no dose at or below this pressure [Pa]", p.tolerance.floor_pressure_pa),
  };
}
#undef NB_FIELD

}  // namespace

double ToleranceCurve::allowedTimeS(double pressure_pa) const {
  if (!(pressure_pa > floor_pressure_pa)) return kInf;
  return reference_time_s * std::pow(reference_pressure_pa / pressure_pa, exponent);
}

Status TissueLoadParams::validate() const {
  ErrorList errors;
  const ToleranceCurve& t = tolerance;
  errors.addIf(!(threshold_pa > 0.0 && threshold_pa <= 1e5), "threshold_pa must lie in (0, 1e5] Pa (got ", threshold_pa,
               ")");
  errors.addIf(!(t.reference_pressure_pa > 0.0 && t.reference_pressure_pa <= 1e6),
               "tolerance/reference_pressure_pa must lie in (0, 1e6] Pa (got ", t.reference_pressure_pa, ")");
  errors.addIf(!(t.reference_time_s > 0.0 && t.reference_time_s <= 1e6),
               "tolerance/reference_time_s must lie in (0, 1e6] s (got ", t.reference_time_s, ")");
  errors.addIf(!(t.exponent > 0.0 && t.exponent <= 10.0), "tolerance/exponent must lie in (0, 10] (got ", t.exponent,
               ")");
  errors.addIf(!(t.floor_pressure_pa >= 0.0 && t.floor_pressure_pa < t.reference_pressure_pa),
               "tolerance/floor_pressure_pa must lie in [0, tolerance/reference_pressure_pa) Pa (got ",
               t.floor_pressure_pa, ")");
  return errors.status();
}

const ParamTable<TissueLoadParams>& tissueLoadParamFields() {
  static const ParamTable<TissueLoadParams> fields = makeFields();
  return fields;
}

const std::vector<TissueRegion>& defaultTissueRegions() {
  static const std::vector<TissueRegion> regions = makeDefaultRegions();
  return regions;
}

std::vector<RegionLoad> measureRegions(const std::vector<ContactPoint>& points,
                                       const std::vector<TissueRegion>& regions, double height_m) {
  // One pass over the points: each point's segment names the regions it may fall in.
  std::vector<std::vector<std::size_t>> regions_of;
  for (std::size_t r = 0; r < regions.size(); ++r)
    for (int seg : regions[r].segments) {
      if (seg < 0) continue;
      if (static_cast<std::size_t>(seg) >= regions_of.size()) regions_of.resize(seg + 1);
      regions_of[seg].push_back(r);
    }
  std::vector<RegionLoad> out(regions.size());
  for (RegionLoad& load : out) load.margin_m = kInf;
  for (const ContactPoint& p : points) {
    if (p.segment < 0 || static_cast<std::size_t>(p.segment) >= regions_of.size()) continue;
    const double along = p.from_vertex_m / height_m;
    const double across = p.half_width_m > 0.0 ? p.lateral_m / p.half_width_m : 0.0;
    for (std::size_t r : regions_of[p.segment]) {
      const TissueRegion& region = regions[r];
      // Half-open windows: a point on a shared edge belongs to one region only.
      if (along < region.from_vertex_min_h || along >= region.from_vertex_max_h) continue;
      if (across < region.lateral_min || across >= region.lateral_max) continue;
      RegionLoad& load = out[r];
      load.margin_m = std::min(load.margin_m, p.skin_height_m);
      if (!(p.pressure_pa > 0.0)) continue;
      load.peak_pressure_pa = std::max(load.peak_pressure_pa, p.pressure_pa);
      load.contact_area_m2 += p.area_m2;
      load.force_n += p.pressure_pa * p.area_m2;
    }
  }
  for (RegionLoad& load : out) {
    if (load.contact_area_m2 > 0.0) load.mean_pressure_pa = load.force_n / load.contact_area_m2;
    if (std::isinf(load.margin_m)) load.margin_m = kNaN;  // no point of the region on the bed
  }
  return out;
}

TissueLoadMeter::TissueLoadMeter(const TissueLoadParams& params, std::vector<TissueRegion> regions)
    : params_(params), regions_(std::move(regions)) {
  const Status valid = params_.validate();
  if (!valid.ok()) throw std::invalid_argument("tissue load parameters: " + valid.message());
  if (regions_.empty()) throw std::invalid_argument("tissue load: no regions to measure");
  reset();
}

void TissueLoadMeter::reset() {
  doses_.assign(regions_.size(), RegionDose{});
  for (RegionDose& d : doses_) d.min_margin_m = kNaN;
  observed_s_ = 0.0;
}

void TissueLoadMeter::sample(const std::vector<RegionLoad>& loads, double dt_s) {
  if (loads.size() != regions_.size()) {
    std::ostringstream m;
    m << "tissue load: got " << loads.size() << " region loads for " << regions_.size() << " regions";
    throw std::invalid_argument(m.str());
  }
  if (!(dt_s >= 0.0 && std::isfinite(dt_s)))
    throw std::invalid_argument("tissue load: the sample's duration must be finite and >= 0 s");
  for (std::size_t r = 0; r < loads.size(); ++r) {
    RegionDose& d = doses_[r];
    const RegionLoad& now = loads[r];
    d.now = now;
    if (now.peak_pressure_pa > params_.threshold_pa) d.time_above_s += dt_s;
    // Cumulative damage (Miner's rule): each interval uses up dt / t_allow of the tolerance.
    d.dose += dt_s / params_.tolerance.allowedTimeS(now.peak_pressure_pa);
    d.max_peak_pressure_pa = std::max(d.max_peak_pressure_pa, now.peak_pressure_pa);
    d.peak_integral_pa_s += now.peak_pressure_pa * dt_s;
    if (std::isfinite(now.margin_m) && !(d.min_margin_m <= now.margin_m)) d.min_margin_m = now.margin_m;
  }
  observed_s_ += dt_s;
}

}  // namespace nursing_bed
