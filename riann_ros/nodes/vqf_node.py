"""vqf_node: attitude from imu/data_raw by VQF (Laidig and Seel).

All behaviour lives in node_base; ``vqf_node --help`` lists its topics and parameters.
"""

from __future__ import annotations

from riann_ros.nodes.node_base import EstimatorNode, run


class VqfNode(EstimatorNode):
    ESTIMATOR = "vqf"
    NODE_NAME = "vqf_node"
    ATTITUDE_TOPIC = "imu/vqf/attitude"
    IMU_TOPIC = "imu/vqf/data"


def main(args: list[str] | None = None) -> int:
    return run(VqfNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
