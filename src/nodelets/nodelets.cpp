// Nodelet shells over the node classes: same code, one process for the whole array.
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

#include <memory>

#include "nursing_bed/ros/airbag_node.h"
#include "nursing_bed/ros/bed_manager.h"

namespace nursing_bed {

/// Runs `Node` in a nodelet; a construction error is logged and leaves the nodelet inert
/// (throwing from onInit would take the whole manager, and every other cell, down).
template <typename Node>
class NodeletShell : public nodelet::Nodelet {
 private:
  void onInit() override {
    try {
      node_ = std::make_unique<Node>(getNodeHandle(), getPrivateNodeHandle());
    } catch (const std::exception& e) {
      NODELET_FATAL("%s", e.what());
    }
  }
  std::unique_ptr<Node> node_;
};

class AirbagNodelet : public NodeletShell<AirbagNode> {};
class BedManagerNodelet : public NodeletShell<BedManager> {};

}  // namespace nursing_bed

PLUGINLIB_EXPORT_CLASS(nursing_bed::AirbagNodelet, nodelet::Nodelet)
PLUGINLIB_EXPORT_CLASS(nursing_bed::BedManagerNodelet, nodelet::Nodelet)
