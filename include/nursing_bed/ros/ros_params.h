// Reading parameter tables from the ROS parameter server: a node's private namespace first,
// then a shared defaults namespace, with unknown keys refused.
#pragma once

#include <ros/node_handle.h>

#include <string>
#include <vector>

#include "nursing_bed/core/io/param_table.h"

namespace nursing_bed {

/// Flattens the parameter tree under `ns` (absolute or relative to `nh`) to "a/b/c" keys;
/// empty when the namespace does not exist. Throws std::runtime_error for non-scalar leaves.
FlatParams flattenRosParams(const ros::NodeHandle& nh, const std::string& ns);

/// The parameters under each of `sections` ("cell", "controller", ...) of the defaults
/// namespace, overridden by the same keys under the node's private namespace, as "section/..."
/// keys. Unknown keys are refused later, by the parameter table they are applied to.
FlatParams layeredRosParams(const ros::NodeHandle& private_nh, const std::string& defaults_ns,
                            const std::vector<std::string>& sections);

}  // namespace nursing_bed
