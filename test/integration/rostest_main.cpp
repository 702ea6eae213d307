// The one main of every rostest node (test/integration/*_test.cpp): gtest, then a ROS node named
// after the executable, kept alive by a NodeHandle while the tests run.
#include <gtest/gtest.h>
#include <ros/ros.h>

#include <string>

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  const std::string exe = argc > 0 ? argv[0] : "rostest_node";
  ros::init(argc, argv, exe.substr(exe.find_last_of('/') + 1));
  ros::NodeHandle nh;
  return RUN_ALL_TESTS();
}
