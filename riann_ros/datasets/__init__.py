"""Dataset readers (ROS-free): each returns :class:`riann_ros.recording.Recording` objects."""
