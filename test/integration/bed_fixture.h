// Shared fixture of the rostests: watches the cells' AirbagState topics and calls services.
#pragma once

#include <gtest/gtest.h>
#include <ros/network.h>
#include <ros/ros.h>
#include <xmlrpcpp/XmlRpcClient.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <string>

#include "nursing_bed/AirbagState.h"
#include "nursing_bed/BedState.h"
#include "nursing_bed/SetHeight.h"
#include "nursing_bed/SetHeights.h"
#include "nursing_bed/SetPosture.h"

namespace nursing_bed {
namespace test {

/// Asks `node` to shut down, as `rosnode kill` does, without its start-up time.
inline void shutdownNode(const std::string& node, const std::string& reason) {
  XmlRpc::XmlRpcValue args, result, payload;
  args[0] = ros::this_node::getName();
  args[1] = node;
  ASSERT_TRUE(ros::master::execute("lookupNode", args, result, payload, true));
  std::string host;
  std::uint32_t port = 0;
  ASSERT_TRUE(ros::network::splitURI(static_cast<std::string>(payload), host, port));
  XmlRpc::XmlRpcClient client(host.c_str(), static_cast<int>(port), "/");
  XmlRpc::XmlRpcValue call, reply;
  call[0] = ros::this_node::getName();
  call[1] = reason;
  ASSERT_TRUE(client.execute("shutdown", call, reply));
}

/// Calls `name` once it is advertised; a call that fails at the transport (no answer at all,
/// not a refusal: every service of the bed answers) is tried once more, as a loaded CI machine
/// can drop a connection. A server that died fails both.
template <class Service>
bool callService(const std::string& name, Service& srv) {
  if (!ros::service::waitForService(name, ros::Duration(10.0))) return false;
  if (ros::service::call(name, srv)) return true;
  ROS_WARN("test: %s gave no answer; trying once more", name.c_str());
  return ros::service::waitForService(name, ros::Duration(5.0)) && ros::service::call(name, srv);
}

class BedFixture : public ::testing::Test {
 protected:
  void SetUp() override {
    ros::NodeHandle pnh("~");
    pnh.param("rows", rows_, 2);
    pnh.param("cols", cols_, 3);
    for (int r = 0; r < rows_; ++r)
      for (int c = 0; c < cols_; ++c) {
        const std::string ns = "/airbag_" + std::to_string(r) + "_" + std::to_string(c);
        const boost::function<void(const AirbagState::ConstPtr&)> on_state = [this](const AirbagState::ConstPtr& m) {
          states_[m->cell_id] = *m;
          ++counts_[m->cell_id];
          const ros::WallTime now = ros::WallTime::now();
          ros::WallTime& last = arrived_[m->cell_id];
          if (!last.isZero()) max_gap_s_ = std::max(max_gap_s_, (now - last).toSec());
          last = now;
          trackStamp(*m);
          max_lag_s_ = std::max(max_lag_s_, (ros::Time::now() - m->header.stamp).toSec());
          trackSetpointRate(*m);
        };
        subs_.push_back(nh_.subscribe<AirbagState>(ns + "/state", 10, on_state));
      }
    ASSERT_TRUE(waitFor([this] { return static_cast<int>(states_.size()) == rows_ * cols_; }, 30.0))
        << "not every cell is publishing its state";
  }

  /// Spins until `condition` holds or `timeout_s` passes; returns whether it held.
  bool waitFor(const std::function<bool()>& condition, double timeout_s) {
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(timeout_s);
    ros::WallRate rate(200.0);
    while (ros::ok() && ros::WallTime::now() < deadline) {
      ros::spinOnce();
      if (condition()) return true;
      rate.sleep();
    }
    ros::spinOnce();
    return condition();
  }

  int cells() const { return rows_ * cols_; }

  /// Waits until every cell is SAFE with its command timeout flagged (the bed manager gone);
  /// returns whether that held within `timeout_s`.
  bool everyCellSafeWithin(double timeout_s) {
    return waitFor(
        [&] {
          for (int id = 0; id < cells(); ++id)
            if (!states_.count(id) || states_[id].mode != AirbagState::MODE_SAFE ||
                !(states_[id].faults & AirbagState::FAULT_COMMAND_TIMEOUT))
              return false;
          return true;
        },
        timeout_s);
  }

  /// Holds when every cell in `targets` (id -> height) has been within tol of it for `hold_s`.
  bool settle(const std::map<uint32_t, double>& targets, double tol_m, double hold_s, double timeout_s) {
    ros::WallTime inside_since;
    return waitFor(
        [&] {
          for (const auto& [id, h] : targets)
            if (!states_.count(id) || std::fabs(states_[id].height_m - h) > tol_m) {
              inside_since = ros::WallTime();
              return false;
            }
          if (inside_since.isZero()) inside_since = ros::WallTime::now();
          return (ros::WallTime::now() - inside_since).toSec() >= hold_s;
        },
        timeout_s);
  }

  /// The largest step between two consecutive stamps of a cell: how far its simulated plant
  /// jumped between two states (the sender's stall, without this process's own scheduling).
  void trackStamp(const AirbagState& m) {
    ros::Time& last = last_stamp_[m.cell_id];
    if (!last.isZero() && m.header.stamp > last) {
      const double gap = (m.header.stamp - last).toSec();
      max_stamp_gap_s_ = std::max(max_stamp_gap_s_, gap);
      ++stamp_steps_;
      if (gap > 0.06) ++stamp_steps_over_60ms_;
    }
    if (m.header.stamp > last) last = m.header.stamp;
  }

  /// The fastest a cell's height setpoint changed over windows of >= 1 s of arrival times (the
  /// manager sends steps at 10 Hz, on the wall clock; a late plant's stamps would compress them).
  /// CPR's NaN restarts the window.
  void trackSetpointRate(const AirbagState& m) {
    auto& [at, value] = setpoint_anchor_[m.cell_id];
    const ros::Time now = ros::Time::now();
    if (!std::isfinite(m.height_setpoint_m) || !std::isfinite(value) || at.isZero()) {
      at = now;
      value = m.height_setpoint_m;
      return;
    }
    const double dt = (now - at).toSec();
    if (dt < 1.0) return;
    max_setpoint_rate_m_s_ = std::max(max_setpoint_rate_m_s_, std::fabs(m.height_setpoint_m - value) / dt);
    at = now;
    value = m.height_setpoint_m;
  }

  SetHeight::Response callCell(const std::string& cell_ns, uint32_t id, double height) {
    SetHeight srv;
    srv.request.cell_id = id;
    srv.request.height_m = height;
    EXPECT_TRUE(callService(cell_ns + "/set_height", srv));
    return srv.response;
  }

  SetHeights::Response callBed(const std::vector<uint32_t>& ids, const std::vector<double>& heights) {
    SetHeights srv;
    srv.request.cell_ids = ids;
    srv.request.heights_m = heights;
    EXPECT_TRUE(callService("/bed_manager/set_airbag_heights", srv));
    return srv.response;
  }

  ros::NodeHandle nh_;
  int rows_ = 2, cols_ = 3;
  std::vector<ros::Subscriber> subs_;
  std::map<uint32_t, AirbagState> states_;
  std::map<uint32_t, int> counts_;
  std::map<uint32_t, ros::WallTime> arrived_;  ///< when each cell's last state arrived
  double max_gap_s_ = 0.0;                     ///< largest gap between two states of a cell [s]
  std::map<uint32_t, ros::Time> last_stamp_;
  double max_stamp_gap_s_ = 0.0;                      ///< largest step of a cell's state stamps [s]
  double max_lag_s_ = 0.0;                            ///< longest a state arrived after the time it describes [s]
  long stamp_steps_ = 0, stamp_steps_over_60ms_ = 0;  ///< steps of the stamps, and those over 60 ms
  std::map<uint32_t, std::pair<ros::Time, double>> setpoint_anchor_;
  double max_setpoint_rate_m_s_ = 0.0;  ///< fastest setpoint change of any cell [m/s]
};

/// BedFixture with the bed manager's state and its posture service.
class PlanFixture : public BedFixture {
 protected:
  void SetUp() override {
    BedFixture::SetUp();
    const boost::function<void(const BedState::ConstPtr&)> on_bed = [this](const BedState::ConstPtr& m) { bed_ = *m; };
    bed_sub_ = nh_.subscribe<BedState>("/bed_manager/state", 5, on_bed);
    ASSERT_TRUE(waitFor([this] { return !bed_.header.stamp.isZero(); }, 10.0));
  }

  SetPosture::Response posture(const std::string& plan, const std::vector<std::string>& keys = {},
                               const std::vector<std::string>& values = {}) {
    SetPosture srv;
    srv.request.plan = plan;
    srv.request.keys = keys;
    srv.request.values = values;
    EXPECT_TRUE(callService("/bed_manager/set_posture", srv));
    return srv.response;
  }

  std::map<uint32_t, double> uniform(double h) const {
    std::map<uint32_t, double> m;
    for (uint32_t id = 0; id < static_cast<uint32_t>(rows_ * cols_); ++id) m[id] = h;
    return m;
  }

  BedState bed_;
  ros::Subscriber bed_sub_;
};

}  // namespace test
}  // namespace nursing_bed
