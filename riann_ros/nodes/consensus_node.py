"""consensus_node: attitude from imu/data_raw by RIANN and VQF in consensus, weighed by their uncertainties.

All behaviour lives in node_base; ``consensus_node --help`` lists its topics and parameters. docs/consensus.md.
"""

from __future__ import annotations

from riann_ros.nodes.node_base import EstimatorNode, run


class ConsensusNode(EstimatorNode):
    ESTIMATOR = "consensus"
    NODE_NAME = "consensus_node"
    ATTITUDE_TOPIC = "imu/consensus/attitude"
    IMU_TOPIC = "imu/consensus/data"


def main(args: list[str] | None = None) -> int:
    return run(ConsensusNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
