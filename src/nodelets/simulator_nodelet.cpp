// Nodelet shell over the simulator: loaded into the airbag manager it reads the cells' states
// and hands them their loads without copies or serialisation.
#include <pluginlib/class_list_macros.hpp>

#include "nursing_bed/ros/nodelet_shell.h"
#include "nursing_bed/ros/simulator.h"

namespace nursing_bed {
class SimulatorNodelet : public NodeletShell<Simulator> {};
}  // namespace nursing_bed

PLUGINLIB_EXPORT_CLASS(nursing_bed::SimulatorNodelet, nodelet::Nodelet)
