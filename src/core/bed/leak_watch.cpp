#include "nursing_bed/core/bed/leak_watch.h"

#include <cmath>
#include <sstream>

namespace nursing_bed {

LeakWatch::LeakWatch(std::size_t cells, double error_m, double duration_s)
    : below_since_s_(cells, CellSnapshot::kNone), error_m_(error_m), duration_s_(duration_s) {}

std::string LeakWatch::update(const BedCell& cell, bool silent, double height_m, double target_m, double now_s) {
  double& since = below_since_s_.at(cell.id);
  if (silent || !std::isfinite(target_m) || !(height_m < target_m - error_m_)) {
    since = CellSnapshot::kNone;
    return "";
  }
  if (!std::isfinite(since)) since = now_s;
  if (!(now_s - since > duration_s_)) return "";
  std::ostringstream a;
  a << "cell " << cell.id << " (" << cell.name << ") low pressure or leak: " << 1e3 * (target_m - height_m)
    << " mm below its target for " << now_s - since << " s";
  return a.str();
}

}  // namespace nursing_bed
