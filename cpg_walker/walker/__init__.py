"""The HOAP-2 walking controller: the generic CPG (cpg/) bound to the robot (robot/), no ROS."""
