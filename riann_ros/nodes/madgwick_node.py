"""madgwick_node: attitude from imu/data_raw by Madgwick's gradient-descent filter.

All behaviour lives in node_base; ``madgwick_node --help`` lists its topics and parameters.
"""

from __future__ import annotations

from riann_ros.nodes.node_base import EstimatorNode, run


class MadgwickNode(EstimatorNode):
    ESTIMATOR = "madgwick"
    NODE_NAME = "madgwick_node"
    ATTITUDE_TOPIC = "imu/madgwick/attitude"
    IMU_TOPIC = "imu/madgwick/data"


def main(args: list[str] | None = None) -> int:
    return run(MadgwickNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
