// One airbag cell as its own process (the same class also runs as nursing_bed/AirbagNodelet).
#include "nursing_bed/ros/airbag_node.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "airbag");
  // The handles outlive a failed construction, so that the fatal message still gets logged.
  ros::NodeHandle nh, private_nh("~");
  try {
    nursing_bed::AirbagNode node(nh, private_nh);
    ros::spin();
  } catch (const std::exception& e) {
    ROS_FATAL("%s", e.what());
    return 1;
  }
  return 0;
}
