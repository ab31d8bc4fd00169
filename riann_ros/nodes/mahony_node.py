"""mahony_node: attitude from imu/data_raw by Mahony's complementary filter.

All behaviour lives in node_base; ``mahony_node --help`` lists its topics and parameters.
"""

from __future__ import annotations

from riann_ros.nodes.node_base import EstimatorNode, run


class MahonyNode(EstimatorNode):
    ESTIMATOR = "mahony"
    NODE_NAME = "mahony_node"
    ATTITUDE_TOPIC = "imu/mahony/attitude"
    IMU_TOPIC = "imu/mahony/data"


def main(args: list[str] | None = None) -> int:
    return run(MahonyNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
