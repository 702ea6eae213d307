// The patient simulator as its own process (the same class also runs as nursing_bed/SimulatorNodelet).
#include "nursing_bed/ros/simulator.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "simulator");
  // Node handles outlive the simulator: when the last one goes, roscpp shuts down and a
  // construction error could no longer be logged.
  ros::NodeHandle nh, private_nh("~");
  try {
    nursing_bed::Simulator node(nh, private_nh);
    ros::spin();
  } catch (const std::exception& e) {
    ROS_FATAL("%s", e.what());
    return 1;
  }
  return 0;
}
