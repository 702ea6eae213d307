// Nodelet shell over the simulator: loaded into the airbag manager it reads the cells' states
// and hands them their loads without copies or serialisation.
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

#include <memory>

#include "nursing_bed/ros/simulator.h"

namespace nursing_bed {

/// A construction error is logged and leaves the nodelet inert (throwing from onInit would take
/// the whole manager, and every cell in it, down).
class SimulatorNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    try {
      simulator_ = std::make_unique<Simulator>(getNodeHandle(), getPrivateNodeHandle());
    } catch (const std::exception& e) {
      NODELET_FATAL("%s", e.what());
    }
  }
  std::unique_ptr<Simulator> simulator_;
};

}  // namespace nursing_bed

PLUGINLIB_EXPORT_CLASS(nursing_bed::SimulatorNodelet, nodelet::Nodelet)
