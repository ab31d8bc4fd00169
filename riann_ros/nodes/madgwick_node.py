"""madgwick_node: Madgwick gradient-descent filter attitude from imu/data_raw (all behaviour lives in node_base)."""

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
