"""semloc on a live ROS 2 robot without ROS: the DDS wire (Cyclone DDS, the `semloc[ros2]`
extra), a node that localizes detections and odometry (`node`), a bag player (`play`)."""
