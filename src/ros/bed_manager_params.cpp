#include "nursing_bed/ros/bed_manager.h"

#include <sstream>
#include <stdexcept>

#include "nursing_bed/ros/ros_params.h"

namespace nursing_bed {

std::string BedManagerParams::validate() const {
  std::ostringstream err;
  if (!(joint_state_rate_hz > 0.0 && joint_state_rate_hz <= 200.0))
    err << "~joint_state_rate_hz must lie in (0, 200]; ";
  if (!(plan_rate_hz > 0.0 && plan_rate_hz <= 100.0)) err << "~plan_rate_hz must lie in (0, 100]; ";
  if (!(diagnostics_rate_hz > 0.0 && diagnostics_rate_hz <= 50.0)) err << "~diagnostics_rate_hz must lie in (0, 50]; ";
  std::string s = err.str() + bed.validate("~");
  if (s.size() >= 2 && s.compare(s.size() - 2, 2, "; ") == 0) s.resize(s.size() - 2);
  return s;
}

BedManagerParams BedManager::loadParams(const ros::NodeHandle& pnh) {
  BedManagerParams p;
  BedSupervisorParams& b = p.bed;
  pnh.param("robot_description_param", p.robot_description, p.robot_description);
  pnh.param("defaults_ns", p.defaults_ns, p.defaults_ns);
  pnh.param("cells_ns", p.cells_ns, p.cells_ns);
  pnh.param("joint_state_rate_hz", p.joint_state_rate_hz, p.joint_state_rate_hz);
  pnh.param("plan_rate_hz", p.plan_rate_hz, p.plan_rate_hz);
  pnh.param("cell_timeout_s", b.cell_timeout_s, b.cell_timeout_s);
  pnh.param("startup_grace_s", b.startup_grace_s, b.startup_grace_s);
  pnh.param("diagnostics_rate_hz", p.diagnostics_rate_hz, p.diagnostics_rate_hz);
  pnh.param("resend_s", b.resend_s, b.resend_s);
  pnh.param("leak_alarm_error_m", b.leak_alarm_error_m, b.leak_alarm_error_m);
  pnh.param("leak_alarm_s", b.leak_alarm_s, b.leak_alarm_s);
  pnh.param("initial_plan", p.initial_plan, p.initial_plan);
  // roslaunch drops an empty value given on its command line (initial_plan:=""): "none" says it.
  if (p.initial_plan == "none") p.initial_plan.clear();
  applyFlatParams(flattenRosParams(pnh, "plans"), "parameters " + pnh.resolveName("plans"), planConfigFields(),
                  &b.plans);
  pnh.param("body/first_row", b.body.first_row, b.body.first_row);
  pnh.param("body/last_row", b.body.last_row, b.body.last_row);
  pnh.param("body/center_y_m", b.body.center_y_m, b.body.center_y_m);
  // Plans must stay inside what the cells accept.
  double cell_max = b.plans.max_height_m;
  pnh.param(p.defaults_ns + "/controller/max_height_m", cell_max, cell_max);
  pnh.param(p.defaults_ns + "/safety/max_height_rate_m_s", b.max_height_rate_m_s, b.max_height_rate_m_s);
  if (b.plans.max_height_m > cell_max) {
    std::ostringstream m;
    m << "bed_manager: ~plans/max_height_m " << b.plans.max_height_m << " m exceeds the cells' controller/max_height_m "
      << cell_max << " m";
    throw std::runtime_error(m.str());
  }
  return p;
}

}  // namespace nursing_bed
