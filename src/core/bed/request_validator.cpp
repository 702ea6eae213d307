#include "nursing_bed/core/bed/request_validator.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

namespace nursing_bed {
namespace {

// Why cell `c` cannot take height `h` now ("" when it can).
std::string checkCell(const BedCell& c, double h, const PlanConfig& limits, const CellHealthWatcher& health,
                      const std::vector<bool>& connected, double now_s) {
  std::ostringstream err;
  if (!std::isfinite(h)) {
    err << "height for cell " << c.id << " is not a finite number";
    return err.str();
  }
  // One source of limits: what a plan may command.
  const double lo = std::max(limits.min_height_m, c.min_height_m);
  const double hi = std::min(limits.max_height_m, c.max_height_m);
  if (h < lo || h > hi) {
    err << "height " << h << " m for cell " << c.id << " (" << c.link_name << ") is outside [" << lo << ", " << hi
        << "] m";
    return err.str();
  }
  if (!health.reporting(c.id, now_s)) return "cell " + std::to_string(c.id) + " (" + c.name + ") is not reporting";
  if (c.id >= connected.size() || !connected[c.id])
    return "cell " + std::to_string(c.id) + " (" + c.name + ") is not connected yet";
  return "";
}

}  // namespace

std::string checkCellHeights(const std::vector<std::uint32_t>& ids, const std::vector<double>& heights_m,
                             const PlanConfig& limits, const CellHealthWatcher& health,
                             const std::vector<bool>& connected, double now_s) {
  if (ids.empty()) return "no cells given";
  if (ids.size() != heights_m.size())
    return std::to_string(ids.size()) + " cell ids but " + std::to_string(heights_m.size()) + " heights";
  const std::vector<BedCell>& cells = health.cells();
  std::set<std::uint32_t> seen;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    if (ids[i] >= cells.size())
      return "cell " + std::to_string(ids[i]) + " does not exist (the bed has " + std::to_string(cells.size()) +
             " cells, ids 0.." + std::to_string(cells.size() - 1) + ")";
    if (!seen.insert(ids[i]).second) return "cell " + std::to_string(ids[i]) + " is given twice";
    const std::string error = checkCell(cells[ids[i]], heights_m[i], limits, health, connected, now_s);
    if (!error.empty()) return error;
  }
  return "";
}

std::string checkRequestText(const std::string& what, const std::string& text, std::size_t max_chars) {
  if (text.size() > max_chars)
    return what + " has " + std::to_string(text.size()) + " characters (at most " + std::to_string(max_chars) + ")";
  for (std::size_t i = 0; i < text.size(); ++i) {
    const auto byte = static_cast<unsigned char>(text[i]);
    if (byte < 0x20 || byte > 0x7e)
      return what + " holds a character that is not printable ASCII (byte " + std::to_string(byte) + " at " +
             std::to_string(i) + ")";
  }
  return "";
}

bool postureRequest(const std::string& plan, const std::vector<std::string>& keys,
                    const std::vector<std::string>& values, const std::vector<double>& heights_m, PlanRequest* request,
                    std::string* error) {
  // Bounded before anything reads or echoes them: a refusal quotes only short printable text.
  *error = checkRequestText("the plan name", plan, kMaxRequestNameChars);
  if (error->empty() && keys.size() > kMaxRequestArguments)
    *error =
        std::to_string(keys.size()) + " arguments (a plan takes at most " + std::to_string(kMaxRequestArguments) + ")";
  for (std::size_t i = 0; i < keys.size() && error->empty(); ++i)
    *error = checkRequestText("argument " + std::to_string(i + 1) + "'s name", keys[i], kMaxRequestNameChars);
  for (std::size_t i = 0; i < values.size() && i < keys.size() && error->empty(); ++i)
    *error = checkRequestText("the value of '" + keys[i] + "'", values[i], kMaxRequestValueChars);
  if (!error->empty()) return false;
  if (keys.size() != values.size()) {
    *error = std::to_string(keys.size()) + " keys but " + std::to_string(values.size()) + " values";
    return false;
  }
  PlanRequest r{plan, {}, heights_m};
  for (std::size_t i = 0; i < keys.size(); ++i) {
    if (!r.args.emplace(keys[i], values[i]).second) {
      *error = "argument '" + keys[i] + "' is given twice";
      return false;
    }
  }
  *request = std::move(r);
  return true;
}

}  // namespace nursing_bed
