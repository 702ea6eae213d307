// The bed manager as its own process (the same class also runs as nursing_bed/BedManagerNodelet).
#include "nursing_bed/ros/bed_manager.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "bed_manager");
  try {
    nursing_bed::BedManager manager(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::exception& e) {
    ROS_FATAL("%s", e.what());
    return 1;
  }
  return 0;
}
