// The bed manager as its own process (the same class also runs as nursing_bed/BedManagerNodelet).
#include "nursing_bed/ros/bed_manager.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "bed_manager");
  // The handles outlive a failed construction, so that the fatal message still gets logged.
  ros::NodeHandle nh, private_nh("~");
  try {
    nursing_bed::BedManager manager(nh, private_nh);
    ros::spin();
  } catch (const std::exception& e) {
    ROS_FATAL("%s", e.what());
    return 1;
  }
  return 0;
}
