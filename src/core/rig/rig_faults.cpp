#include "nursing_bed/core/rig/rig_faults.h"

#include <algorithm>
#include <cmath>
#include <map>

#include "nursing_bed/core/io/errors.h"

namespace nursing_bed {
namespace {

const std::map<std::string, RigFaultKind>& kinds() {
  static const std::map<std::string, RigFaultKind> table{
      {"clear", RigFaultKind::kClear},
      {"stuck_open", RigFaultKind::kStuckOpen},
      {"stuck_closed", RigFaultKind::kStuckClosed},
      {"frozen_sensor", RigFaultKind::kFrozenSensor},
      {"sensor_offset", RigFaultKind::kSensorOffset},
      {"leak", RigFaultKind::kLeak},
      {"drop_replies", RigFaultKind::kDropReplies},
      {"delay_replies", RigFaultKind::kDelayReplies},
      {"restart", RigFaultKind::kRestart},
  };
  return table;
}

constexpr double kMaxOffsetPa = 50000.0;
constexpr double kMaxSilenceS = 60.0;
constexpr double kMaxDelayS = 2.0;

void checkValue(RigFaultKind kind, const RigFaultRequest& r, double vent_area_m2, ErrorList* errors) {
  const double v = r.value;
  switch (kind) {
    case RigFaultKind::kStuckOpen:
    case RigFaultKind::kStuckClosed:
      errors->addIf(r.valve != "inlet" && r.valve != "vent", "valve must be inlet or vent, got '", r.valve, "'");
      break;
    case RigFaultKind::kSensorOffset:
      errors->addIf(!(std::fabs(v) <= kMaxOffsetPa), "sensor_offset value must be an offset within +-", kMaxOffsetPa,
                    " Pa, got ", v);
      break;
    case RigFaultKind::kLeak:
      errors->addIf(!(v > 0.0 && v <= vent_area_m2), "leak value must be an area in (0, ", vent_area_m2,
                    "] m^2 (the vent's), got ", v);
      break;
    case RigFaultKind::kDropReplies:
    case RigFaultKind::kDelayReplies:
      errors->addIf(!(v >= 0.0 && v <= 1.0), r.fault, " value must be a probability in [0, 1], got ", v);
      errors->addIf(kind == RigFaultKind::kDelayReplies && !(r.delay_s > 0.0 && r.delay_s <= kMaxDelayS),
                    "delay_replies delay_s must lie in (0, ", kMaxDelayS, "] s, got ", r.delay_s);
      break;
    case RigFaultKind::kRestart:
      errors->addIf(!(v >= 0.0 && v <= kMaxSilenceS), "restart value must be the silence in [0, ", kMaxSilenceS,
                    "] s, got ", v);
      break;
    case RigFaultKind::kClear:
    case RigFaultKind::kFrozenSensor: break;
  }
}

}  // namespace

ValveOpenings CellFaults::apply(const ValveOpenings& commanded, double vent_area_m2) const {
  ValveOpenings v = commanded;
  if (stuck_inlet >= 0) v.inlet = stuck_inlet;
  if (stuck_vent >= 0) v.vent = stuck_vent;
  if (leak_area_m2 > 0.0 && vent_area_m2 > 0.0) v.vent = std::min(1.0, v.vent + leak_area_m2 / vent_area_m2);
  return v;
}

std::string rigFaultNames() {
  std::string names;
  for (const auto& [name, kind] : kinds()) names += (names.empty() ? "" : ", ") + name;
  return names;
}

Status checkRigFault(const RigFaultRequest& request, const std::vector<std::uint32_t>& served_ids, double vent_area_m2,
                     RigFaultKind* kind) {
  ErrorList errors;
  const auto found = kinds().find(request.fault);
  if (found == kinds().end()) {
    errors.add("unknown fault '", request.fault, "' (one of ", rigFaultNames(), ")");
    return errors.status();
  }
  for (const std::uint32_t id : request.cell_ids)
    errors.addIf(std::find(served_ids.begin(), served_ids.end(), id) == served_ids.end(), "cell ", id,
                 " is not served by the emulator");
  errors.addIf(request.random_cells < 0 || request.random_cells > static_cast<int>(served_ids.size()),
               "random_cells must lie in [0, ", served_ids.size(), "], got ", request.random_cells);
  errors.addIf(request.random_cells > 0 && !request.cell_ids.empty(), "give cell_ids or random_cells, not both");
  checkValue(found->second, request, vent_area_m2, &errors);
  if (errors.ok()) *kind = found->second;
  return errors.status();
}

std::vector<std::uint32_t> rigFaultCells(const RigFaultRequest& request, const std::vector<std::uint32_t>& served_ids,
                                         std::mt19937* rng) {
  if (!request.cell_ids.empty()) return request.cell_ids;
  if (request.random_cells <= 0) return served_ids;
  std::vector<std::uint32_t> ids = served_ids;
  std::shuffle(ids.begin(), ids.end(), *rng);
  ids.resize(static_cast<std::size_t>(request.random_cells));
  std::sort(ids.begin(), ids.end());
  return ids;
}

void applyCellFault(RigFaultKind kind, const RigFaultRequest& request, CellFaults* faults) {
  switch (kind) {
    case RigFaultKind::kClear: *faults = CellFaults{}; break;
    case RigFaultKind::kStuckOpen:
    case RigFaultKind::kStuckClosed:
      (request.valve == "inlet" ? faults->stuck_inlet : faults->stuck_vent) = kind == RigFaultKind::kStuckOpen ? 1 : 0;
      break;
    case RigFaultKind::kFrozenSensor: faults->frozen = true; break;
    case RigFaultKind::kSensorOffset: faults->offset_pa = request.value; break;
    case RigFaultKind::kLeak: faults->leak_area_m2 = request.value; break;
    case RigFaultKind::kDropReplies:
    case RigFaultKind::kDelayReplies:
    case RigFaultKind::kRestart: break;  // the terminals' and the plant's, not the cell's registers
  }
}

}  // namespace nursing_bed
