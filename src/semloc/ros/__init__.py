"""ROS 2 glue without ROS: recorded runs (rosbag2, MCAP) in, answers as MCAP out.

`stream` holds the logic of a streaming relocalizer fed by a 3D detector (plain numpy, what a
live ROS 2 node wraps); `bag` reads runs and `mcap_out` / `answers` write the answers as ROS 2
messages through `rosbags` and `mcap` (the `semloc[ros]` extra, imported on first use);
`messages` is the type store, `frames` the poses, stamps and covariances, `simbag` a simulated
walk as a bag.
"""

from semloc.ros.stream import BoxDetection, DetectionFrame, StreamLocalizer, box_surface

__all__ = ["BoxDetection", "DetectionFrame", "StreamLocalizer", "box_surface"]
