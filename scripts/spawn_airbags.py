#!/usr/bin/python3
"""Loads one nursing_bed/AirbagNodelet per cell into a nodelet manager (one process for the
whole array instead of one `nodelet load` process per cell) and unloads them on shutdown.

Private parameters: ~rows, ~cols (the bed layout), ~manager (default /airbag_manager),
~type (default nursing_bed/AirbagNodelet), ~load_n [N], ~initial_height_m [m], ~cells_ns
(default /). Each cell gets its ~row, ~col, ~load_n, ~initial_height_m parameters set before
it is loaded."""
import sys

import rospy
from nodelet.srv import NodeletLoad, NodeletUnload


def main():
    rospy.init_node("airbag_spawner")
    rows = rospy.get_param("~rows")
    cols = rospy.get_param("~cols")
    if not (isinstance(rows, int) and isinstance(cols, int) and 1 <= rows <= 100 and 1 <= cols <= 100):
        rospy.logfatal("airbag_spawner: ~rows and ~cols must be whole numbers in 1..100, got %r x %r", rows, cols)
        sys.exit(2)
    manager = rospy.get_param("~manager", "/airbag_manager")
    nodelet_type = rospy.get_param("~type", "nursing_bed/AirbagNodelet")
    load_n = float(rospy.get_param("~load_n", 0.6))
    initial_height_m = float(rospy.get_param("~initial_height_m", 0.0))
    cells_ns = rospy.get_param("~cells_ns", "/").rstrip("/") + "/"

    rospy.wait_for_service(manager + "/load_nodelet")
    load = rospy.ServiceProxy(manager + "/load_nodelet", NodeletLoad, persistent=True)
    loaded = []
    for row in range(rows):
        for col in range(cols):
            name = "%sairbag_%d_%d" % (cells_ns, row, col)
            rospy.set_param(name + "/row", row)
            rospy.set_param(name + "/col", col)
            rospy.set_param(name + "/load_n", load_n)
            rospy.set_param(name + "/initial_height_m", initial_height_m)
            if not load(name, nodelet_type, [], [], [], "").success:
                rospy.logfatal("airbag_spawner: manager %s refused to load %s", manager, name)
                sys.exit(1)
            loaded.append(name)
    rospy.loginfo("airbag_spawner: %d airbag nodelets loaded into %s", len(loaded), manager)

    def unload_all():
        try:
            unload = rospy.ServiceProxy(manager + "/unload_nodelet", NodeletUnload)
            for name in loaded:
                unload(name)
        except (rospy.ServiceException, rospy.ROSException):
            pass  # the manager is already gone

    rospy.on_shutdown(unload_all)
    rospy.spin()


if __name__ == "__main__":
    main()
