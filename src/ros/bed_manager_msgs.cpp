#include "nursing_bed/ros/bed_manager_msgs.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "nursing_bed/ros/names.h"

namespace nursing_bed {
namespace {

uint8_t diagnosticLevel(Severity s) {
  using D = diagnostic_msgs::DiagnosticStatus;
  return s == Severity::kError ? D::ERROR : (s == Severity::kWarn ? D::WARN : D::OK);
}

diagnostic_msgs::KeyValue keyValue(const std::string& key, const std::string& value) {
  diagnostic_msgs::KeyValue pair;
  pair.key = key;
  pair.value = value;
  return pair;
}

}  // namespace

BedGrid bedGrid(const BedLayout& layout) {
  BedGrid g;
  g.rows = layout.rows();
  g.cols = layout.cols();
  g.pitch_m = layout.pitchM();
  g.min_height_m = layout.cells().front().min_height_m;
  g.max_height_m = layout.cells().front().max_height_m;
  return g;
}

std::vector<BedCell> bedCells(const BedLayout& layout) {
  std::vector<BedCell> cells;
  for (const CellLayout& c : layout.cells())
    cells.push_back({c.id, names::airbagName(c.row, c.col), c.link_name, c.min_height_m, c.max_height_m});
  return cells;
}

CellSnapshot cellSnapshot(const AirbagState& s, double seen_s) {
  return CellSnapshot{s.cell_id,           s.height_m,        s.height_sd_m, s.faults,
                      s.gauge_pressure_pa, s.external_load_n, seen_s,        s.height_unverified != 0};
}

BedState bedStateMsg(const BedStatus& status, const ros::Time& stamp) {
  BedState m;
  m.header.stamp = stamp;
  m.plan = status.plan ? planKindName(*status.plan) : "";
  m.phase = status.phase;
  m.parameters = status.parameters;
  m.elapsed_s = status.elapsed_s;
  m.tilt_deg = status.tilt_deg;
  m.target_heights_m = status.target_heights_m;
  m.dead_cells = status.dead_cells;
  m.largest_state_gap_s = status.largest_state_gap_s;
  m.faulty_cells = status.faulty_cells;
  m.unverified_cells = status.unverified_cells;
  m.alarms = status.alarms;
  return m;
}

diagnostic_msgs::DiagnosticArray diagnosticsMsg(const BedReport& report, const BedLayout& layout,
                                                const std::vector<AirbagState>& last, const CellHealthWatcher& health,
                                                const ros::Time& stamp) {
  diagnostic_msgs::DiagnosticArray array;
  array.header.stamp = stamp;
  diagnostic_msgs::DiagnosticStatus bed;
  bed.name = "bed";
  bed.hardware_id = "nursing_bed";
  bed.level = diagnosticLevel(report.severity);
  bed.message = report.message;
  for (const std::string& a : report.alarms) bed.values.push_back(keyValue("alarm", a));
  if (!report.plan.empty()) bed.values.push_back(keyValue("plan", report.plan));
  array.status.push_back(bed);
  for (const CellLayout& c : layout.cells()) {
    diagnostic_msgs::DiagnosticStatus s;
    s.name = "bed/" + names::airbagName(c.row, c.col);
    s.hardware_id = "cell " + std::to_string(c.id);
    s.level = diagnosticLevel(report.cells.at(c.id).severity);
    s.message = report.cells.at(c.id).message;
    if (health.reported(c.id)) {
      const AirbagState& st = last.at(c.id);
      s.values.push_back(keyValue("height_m", std::to_string(st.height_m)));
      s.values.push_back(keyValue("gauge_pressure_pa", std::to_string(st.gauge_pressure_pa)));
      s.values.push_back(keyValue("height_setpoint_m", std::to_string(st.height_setpoint_m)));
      s.values.push_back(keyValue("external_load_n", std::to_string(st.external_load_n)));
      s.values.push_back(keyValue("faults", std::to_string(static_cast<double>(st.faults))));
      s.values.push_back(keyValue("height_unverified", st.height_unverified ? "true" : "false"));
    }
    array.status.push_back(s);
  }
  return array;
}

sensor_msgs::JointState jointStatesMsg(const BedLayout& layout, const std::vector<AirbagState>& last,
                                       const CellHealthWatcher& health, const ros::Time& stamp) {
  sensor_msgs::JointState js;
  js.header.stamp = stamp;
  for (const CellLayout& c : layout.cells()) {
    if (!health.reported(c.id)) continue;  // unknown height: leave the joint out
    js.name.push_back(c.joint_name);
    const double h = last.at(c.id).height_m;
    js.position.push_back(std::isfinite(h) ? std::clamp(h, c.min_height_m, c.max_height_m) : 0.0);
  }
  return js;
}

BedHeights bedHeightsMsg(const BedLayout& layout, const std::vector<AirbagState>& last, const CellHealthWatcher& health,
                         const ros::Time& stamp) {
  BedHeights out;
  out.header.stamp = stamp;
  const std::size_t n = layout.cells().size();
  out.stamps.assign(n, ros::Time());
  out.height_m.assign(n, CellSnapshot::kNone);
  out.height_sd_m.assign(n, CellSnapshot::kNone);
  out.height_source.assign(n, AirbagState::HEIGHT_MEASURED);
  for (const CellLayout& c : layout.cells()) {
    if (!health.reported(c.id)) continue;
    const AirbagState& s = last.at(c.id);
    out.stamps[c.id] = s.header.stamp;
    out.height_m[c.id] = s.height_m;
    out.height_sd_m[c.id] = s.height_sd_m;
    out.height_source[c.id] = s.height_source;
  }
  return out;
}

}  // namespace nursing_bed
