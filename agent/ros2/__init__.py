"""The optional ROS 2 interface (``[ros2]``, docs/ros2.md): a ROS 2 robot's scans, odometry and
tf in over Zenoh, the places and markers back, as CDR bytes through ``rosbags``."""
