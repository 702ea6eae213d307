// Nodelet shells over the node classes: same code, one process for the whole array.
#include <pluginlib/class_list_macros.hpp>

#include "nursing_bed/ros/airbag_node.h"
#include "nursing_bed/ros/bed_manager.h"
#include "nursing_bed/ros/nodelet_shell.h"

namespace nursing_bed {
class AirbagNodelet : public NodeletShell<AirbagNode> {};
class BedManagerNodelet : public NodeletShell<BedManager> {};
}  // namespace nursing_bed

PLUGINLIB_EXPORT_CLASS(nursing_bed::AirbagNodelet, nodelet::Nodelet)
PLUGINLIB_EXPORT_CLASS(nursing_bed::BedManagerNodelet, nodelet::Nodelet)
