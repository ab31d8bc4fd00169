"""ROS 2 nodes: a thin layer over the core (see node_base.py)."""
