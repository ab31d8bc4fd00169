"""The ROS layer's tools (rclpy): what talks to the estimator nodes over DDS from outside them.

- :mod:`~riann_ros.ros.dds_replay`: the replay that ``riann-bag-eval --live`` drives (the evaluator's side,
  :class:`riann_ros.evaluation.live.LiveRunner`, meets it through :mod:`riann_ros.replay`), with the nodes it starts
  (:mod:`~riann_ros.ros.started_nodes`);
- :mod:`~riann_ros.ros.topics`: ``riann-topic``'s reader of the DDS graph;
- :mod:`~riann_ros.ros.services`: a service call that survives a lost first answer.

Like :mod:`riann_ros.nodes` (the nodes themselves), it imports the core and the ROS layer only, never the evaluator
or the CLIs.
"""
