#include "nursing_bed/core/observer/weight_bound.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace nursing_bed {
namespace {
// Rests of the plate alone tabulated up to the bag's top (the weight bound, the flat test).
constexpr int kPlateAloneRests = 80;
}  // namespace

void WeightBound::tabulate(const CellStructure& structure, double plate_weight_n, double top_m) {
  const double top = 0.95 * top_m;
  h_m_.clear();
  p_pa_.clear();
  for (int i = 1; i <= kPlateAloneRests; ++i) {
    const double h = top * i / kPlateAloneRests;
    const StructureEquilibrium e = structure.equilibriumAtHeight(h, plate_weight_n);
    h_m_.push_back(h);
    p_pa_.push_back(e.converged && e.gauge_pressure_pa > 0.0 ? e.gauge_pressure_pa
                                                             : std::numeric_limits<double>::quiet_NaN());
  }
}

double WeightBound::lowestLiftedPressure() const {
  double lowest = std::numeric_limits<double>::infinity();
  for (const double p : p_pa_)
    if (std::isfinite(p)) lowest = std::min(lowest, p);
  return lowest;
}

double WeightBound::plateAloneHeight(double gauge_pressure_pa) const {
  // From the top down, the first rest the pressure can hold: above it every rest needs more
  // (a rest not found counts as holdable, so it never tightens the bound). Interpolated in the
  // pressure's logarithm between neighbouring rests (the rest pressure grows about
  // exponentially towards the bag's top).
  const std::size_t n = p_pa_.size();
  for (std::size_t k = n; k-- > 0;) {
    const double p = p_pa_[k];
    if (std::isfinite(p) && p > gauge_pressure_pa) continue;
    if (k + 1 == n) return std::numeric_limits<double>::infinity();
    if (!std::isfinite(p) || gauge_pressure_pa <= 0.0) return h_m_[k];
    const double p_up = p_pa_[k + 1];
    const double f = std::log(gauge_pressure_pa / p) / std::log(p_up / p);
    return h_m_[k] + std::clamp(f, 0.0, 1.0) * (h_m_[k + 1] - h_m_[k]);
  }
  return h_m_.empty() ? std::numeric_limits<double>::infinity() : h_m_.front();
}

void WeightBound::reset() {
  quiet_.reset();
  lifting_.reset();
}

bool WeightBound::Window::mean(double gauge_pressure_pa, bool holds, double dt_s, const ReadingNoise& noise,
                               double* mean_pa, double* se_pa) {
  // While the condition holds the plate first settles for one window, then the readings are
  // averaged for as long as it keeps holding; true at the end of each window.
  if (length_s <= 0.0 || !holds) {
    reset();
    return false;
  }
  held_s += dt_s;
  if (held_s <= length_s) return false;
  sum_pa += gauge_pressure_pa;
  ++count;
  const double since_settled = held_s - length_s;
  if (std::floor(since_settled / length_s) == std::floor((since_settled - dt_s) / length_s)) return false;
  *mean_pa = sum_pa / static_cast<double>(count);
  *se_pa = noise.meanSd(static_cast<double>(count));
  if (!cumulative) sum_pa = 0.0, count = 0;
  return true;
}

}  // namespace nursing_bed
