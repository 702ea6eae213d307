// Checks of the requests the bed supervisor takes from outside (ROS-free): manual cell heights
// and the arguments of a posture request. Each refusal names the wrong entry; a refused request
// changes nothing. A plan's own arguments are checked by makePlan.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "nursing_bed/core/bed/cell_health.h"
#include "nursing_bed/core/bed/posture_plans.h"

namespace nursing_bed {

/// Empty when setting `heights_m` on the cells `ids` is valid at `now_s`, else why not: every id
/// a cell and given once, every height finite and within the plan limits and the cell's range,
/// every cell reporting and `connected` (by cell id: something listens to its setpoints).
std::string checkCellHeights(const std::vector<std::uint32_t>& ids, const std::vector<double>& heights_m,
                             const PlanConfig& limits, const CellHealthWatcher& health,
                             const std::vector<bool>& connected, double now_s);

/// Longest plan name or argument name, most arguments, longest argument value a posture
/// request may carry (a value is longer than any number the plans read: kMaxNumberChars).
constexpr std::size_t kMaxRequestNameChars = 64, kMaxRequestArguments = 32, kMaxRequestValueChars = 256;

/// Empty when `text` has at most `max_chars` characters, all printable ASCII; else why not,
/// naming it `what` (the text itself is not quoted).
std::string checkRequestText(const std::string& what, const std::string& text, std::size_t max_chars);

/// The request of a posture service call: `plan`, the arguments as parallel `keys` and
/// `values`, and per-cell `heights_m`. False, with why in *error, when a name or value is too
/// long or not printable ASCII, there are too many arguments, keys and values differ in number
/// or a key is given twice.
bool postureRequest(const std::string& plan, const std::vector<std::string>& keys,
                    const std::vector<std::string>& values, const std::vector<double>& heights_m, PlanRequest* request,
                    std::string* error);

}  // namespace nursing_bed
