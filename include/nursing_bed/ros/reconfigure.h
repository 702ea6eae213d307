// dynamic_reconfigure for what an operator tunes on a running bed: the cells' controller and
// safety thresholds (cfg/AirbagCell.cfg) and the bed manager's alarms and plan defaults
// (cfg/BedManager.cfg). A reconfigure parameter's name is the node's YAML key with its '/'
// written '_' (controller/height_tolerance_m -> controller_height_tolerance_m); a request is
// applied to a copy of the node's parameters, checked by the same validate() as at start-up,
// and taken whole or refused whole. Interface: doc/airbag_node.md, doc/bed_manager.md.
#pragma once

#include <dynamic_reconfigure/server.h>
#include <ros/node_handle.h>

#include <boost/thread/recursive_mutex.hpp>
#include <functional>
#include <map>
#include <string>

#include "nursing_bed/AirbagCellConfig.h"
#include "nursing_bed/BedManagerConfig.h"
#include "nursing_bed/ros/airbag_node.h"
#include "nursing_bed/ros/bed_manager.h"

namespace nursing_bed {

/// What an accepted request changed: YAML key ("controller/hold_band_m") -> new value.
using ReconfiguredKeys = std::map<std::string, double>;

/// The YAML key of a reconfigure parameter: "controller_hold_band_m" -> "controller/hold_band_m"
/// for the airbag's sections (controller, safety) and the bed manager's (plans); other names
/// are top-level keys and stay as they are.
std::string reconfigureYamlKey(const std::string& name);

/// The configuration showing `params`' values (what a server starts with, instead of the cfg
/// defaults). Throws std::logic_error when a cfg parameter has no key in the parameter tables.
AirbagCellConfig airbagConfigFrom(const AirbagNodeParams& params);
BedManagerConfig bedManagerConfigFrom(const BedManagerParams& params);

/// `config`'s values over a copy of *params, checked by the node's validate(). Valid: *params
/// takes the copy, *changed the keys whose value differs, and the result is empty. Invalid: the
/// result names the requested changes and what is wrong; *params and *changed stay untouched.
std::string reconfigureParams(const AirbagCellConfig& config, AirbagNodeParams* params, ReconfiguredKeys* changed);
std::string reconfigureParams(const BedManagerConfig& config, BedManagerParams* params, ReconfiguredKeys* changed);

/// A node's reconfigure callback: reconfigureParams(), and on refusal a ROS_ERROR naming `who`,
/// the keys and why, with `config` set back to *params' values (the server then sends those
/// back as the current ones). True when accepted with a change: the caller applies *params.
bool reconfigureRequest(AirbagCellConfig& config, AirbagNodeParams* params, ReconfiguredKeys* changed,
                        const std::string& who);
bool reconfigureRequest(BedManagerConfig& config, BedManagerParams* params, ReconfiguredKeys* changed,
                        const std::string& who);

/// Writes accepted changes under their YAML keys in `private_nh`, where loadParams() reads them:
/// a restarted node starts with the tuned values. Call without the node's lock held.
void saveReconfigured(const ros::NodeHandle& private_nh, const ReconfiguredKeys& changed);

/// A dynamic_reconfigure server in `private_nh` whose configuration starts as `initial` (the
/// node's loaded values: neither the cfg defaults nor values a previous run left on the server
/// overwrite its YAML values); `callback` gets every request after that.
template <class Config>
class ReconfigureServer {
 public:
  using Callback = std::function<void(Config&)>;
  ReconfigureServer(const ros::NodeHandle& private_nh, const Config& initial, Callback callback)
      : server_(mutex_, private_nh) {
    // setCallback's own first call takes `initial` in place of what the server read, then
    // publishes and mirrors it: one write of the configuration where updateConfig() would add
    // another (each parameter a call to the master, for every cell of the bed).
    bool started = false;
    server_.setCallback([started, initial, callback = std::move(callback)](Config& config, uint32_t) mutable {
      if (started) return callback(config);
      config = initial;
      started = true;
    });
  }

 private:
  boost::recursive_mutex mutex_;  ///< the server's (declared first: it outlives server_)
  dynamic_reconfigure::Server<Config> server_;
};

}  // namespace nursing_bed
