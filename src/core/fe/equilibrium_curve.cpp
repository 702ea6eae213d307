#include "nursing_bed/core/fe/equilibrium_curve.h"

#include <algorithm>
#include <cstdio>

namespace nursing_bed {
namespace fe {

std::vector<LoadedState> equilibriumCurve(std::vector<LoadedState> states, std::vector<std::string>* left_out) {
  std::sort(states.begin(), states.end(),
            [](const LoadedState& x, const LoadedState& y) { return x.load_n < y.load_n; });
  std::vector<LoadedState> curve;
  for (const LoadedState& s : states) {
    if (curve.empty() || s.height_m < curve.back().height_m - 1e-4) {
      curve.push_back(s);
    } else if (left_out) {
      char text[160];
      std::snprintf(text, sizeof(text), "the %.1f N state (h %.1f mm) is not below the %.1f N one (h %.1f mm)",
                    s.load_n, s.height_m * 1e3, curve.back().load_n, curve.back().height_m * 1e3);
      left_out->push_back(text);
    }
  }
  return curve;
}

bool onEquilibriumCurve(const std::vector<LoadedState>& curve, double height_m, double* force_n, double* volume_m3) {
  if (curve.size() < 2 || height_m > curve.front().height_m || height_m < curve.back().height_m) return false;
  for (std::size_t k = 0; k + 1 < curve.size(); ++k) {
    const LoadedState& hi = curve[k];
    const LoadedState& lo = curve[k + 1];
    if (height_m <= hi.height_m && height_m >= lo.height_m) {
      const double f = (height_m - lo.height_m) / (hi.height_m - lo.height_m);
      *force_n = lo.load_n + f * (hi.load_n - lo.load_n);
      *volume_m3 = lo.volume_m3 + f * (hi.volume_m3 - lo.volume_m3);
      return true;
    }
  }
  return false;
}

}  // namespace fe
}  // namespace nursing_bed
