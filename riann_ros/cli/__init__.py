"""Command-line tools (thin verbs over the ROS-free core)."""
