"""riann_node: attitude from imu/data_raw by RIANN, a recurrent neural network that needs no tuning.

All behaviour lives in node_base; ``riann_node --help`` lists its topics and parameters.
"""

from __future__ import annotations

from riann_ros.nodes.node_base import EstimatorNode, run


class RiannNode(EstimatorNode):
    ESTIMATOR = "riann"
    NODE_NAME = "riann_node"
    ATTITUDE_TOPIC = "imu/attitude"
    IMU_TOPIC = "imu/data"


def main(args: list[str] | None = None) -> int:
    return run(RiannNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
