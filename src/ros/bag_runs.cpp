#include "nursing_bed/ros/bag_runs.h"

#include <rosbag/bag.h>
#include <rosbag/view.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/AirbagState.h"

namespace nursing_bed {
namespace {

const std::string kAirbagStateType = "nursing_bed/AirbagState";

}  // namespace

std::vector<RunData> readRunsFromBag(const std::string& path) {
  rosbag::Bag bag;
  try {
    bag.open(path, rosbag::bagmode::Read);
  } catch (const rosbag::BagException& e) {
    throw std::runtime_error(path + ": cannot open bag: " + e.what());
  }
  const std::string stem = std::filesystem::path(path).stem().string();

  // One view over all AirbagState connections; messages arrive in record-time order.
  std::map<std::string, RunData> runs;
  std::map<std::string, bool> use_record_time;
  std::map<std::string, double> first_time;
  try {
    rosbag::View view(bag, rosbag::TypeQuery(kAirbagStateType));
    for (const rosbag::MessageInstance& m : view) {
      const std::string& topic = m.getTopic();
      const nursing_bed::AirbagState::ConstPtr msg = m.instantiate<nursing_bed::AirbagState>();
      if (!msg)
        throw std::runtime_error(path + ": topic " + topic + ": cannot read as " + kAirbagStateType +
                                 " (message definition differs)");
      RunData& run = runs[topic];
      if (run.t_s.empty()) {
        run.name = stem + (topic.empty() || topic[0] != '/' ? "/" : "") + topic;
        run.source = path;
        run.meta["nursing_bed_run"] = std::to_string(kRunCsvVersion);
        run.meta["bag"] = path;
        run.meta["topic"] = topic;
        // AirbagState's inflow and valve openings are means since the previous message.
        run.flow_interval_means = true;
        run.load_n = msg->external_load_n;
        run.meta["load_n"] = std::to_string(msg->external_load_n);
        use_record_time[topic] = msg->header.stamp.isZero();
        first_time[topic] = use_record_time[topic] ? m.getTime().toSec() : msg->header.stamp.toSec();
      }
      const double stamp = use_record_time[topic] ? m.getTime().toSec() : msg->header.stamp.toSec();
      const double t = stamp - first_time[topic];
      // A cell repeats its last state (same stamp) while its simulated plant runs late
      // (doc/safety.md): a repeat carries nothing new and is skipped; time going back is an error.
      if (!use_record_time[topic] && !run.t_s.empty() && t == run.t_s.back()) continue;
      if (!run.t_s.empty() && !(t > run.t_s.back())) {
        std::ostringstream what;
        what << path << ": topic " << topic << ": time not strictly increasing at message " << run.t_s.size() << " ("
             << t << " s after " << run.t_s.back() << " s; "
             << (use_record_time[topic] ? "record time" : "header.stamp") << ")";
        throw std::runtime_error(what.str());
      }
      run.t_s.push_back(t);
      run.mdot_in_kg_s.push_back(msg->inflow_kg_s);
      run.p_gauge_pa.push_back(msg->gauge_pressure_pa);
      run.h_m.push_back(msg->height_m);
      run.load_n_series.push_back(msg->external_load_n);
      // The vent's opening whenever it was open (the inlet's gas is metered anyway; the vent's
      // is not, and a replay needs its opening), else the inlet's.
      run.valve_cmd.push_back(msg->vent_valve_cmd > 0.0 ? -msg->vent_valve_cmd : msg->inlet_valve_cmd);
      run.t_gas_k.push_back(msg->gas_temperature_k);
    }
  } catch (const rosbag::BagException& e) {
    throw std::runtime_error(path + ": cannot read bag: " + e.what());
  }
  if (runs.empty()) throw std::runtime_error(path + ": no " + kAirbagStateType + " topic in the bag");
  std::vector<RunData> out;
  for (auto& [topic, run] : runs) {
    if (run.t_s.size() < 2)
      throw std::runtime_error(path + ": topic " + topic + ": " + std::to_string(run.t_s.size()) +
                               " message(s), a run needs at least 2");
    out.push_back(std::move(run));
  }
  return out;
}

}  // namespace nursing_bed
