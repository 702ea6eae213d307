// The rig emulator: Modbus TCP terminals on 127.0.0.1 over simulated cells (doc/real_bed.md).
#include "nursing_bed/ros/rig_emulator_node.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "rig_emulator");
  ros::NodeHandle nh, private_nh("~");
  try {
    nursing_bed::RigEmulatorNode node(nh, private_nh);
    ros::spin();
  } catch (const std::exception& e) {
    ROS_FATAL("%s", e.what());
    return 1;
  }
  return 0;
}
