"""riann-topic's reader of the DDS graph (riann_ros.ros.topics): message classes by type name, and the error when a
topic's type is not the one asked for, over real DDS. The command itself: test_cli_topic.py."""

from __future__ import annotations

import pytest

from conftest import wait_for
from riann_ros.ros.topics import TopicError, TopicTool, message_class


def test_message_class_by_type_name():
    cls = message_class("geometry_msgs/msg/Vector3Stamped")
    assert cls.__name__ == "Vector3Stamped" and message_class("geometry_msgs/Vector3Stamped") is cls
    with pytest.raises(TopicError, match="must be pkg/msg/Name"):
        message_class("Vector3Stamped")
    with pytest.raises(TopicError, match="no_such_msgs/msg/Thing is not installed in this Python"):
        message_class("no_such_msgs/msg/Thing")


@pytest.mark.ros
def test_a_type_mismatch_seen_after_subscribing_is_named(ros):
    """--type given and the publisher discovered only after the subscription: the graph then lists the topic with
    both types (this reader's own among them), and the error must still name the publisher's type."""
    from geometry_msgs.msg import QuaternionStamped

    pub_side, reader = TopicTool(), TopicTool()
    try:
        reader.subscribe("/late/attitude", "sensor_msgs/msg/Imu", "reliable", lambda m: None)
        pub_side.node.create_publisher(QuaternionStamped, "/late/attitude", 10)

        def discovered() -> bool:
            pub_side.spin_for(0.05)
            reader.spin_for(0.05)
            return len(reader.topics().get("/late/attitude", [])) == 2

        wait_for(discovered, 60, "the publisher in the reader's graph")
        err = str(reader.no_message("/late/attitude", "sensor_msgs/msg/Imu", 5))
        assert err == "/late/attitude has type geometry_msgs/msg/QuaternionStamped, not sensor_msgs/msg/Imu"
        assert "no message" in str(reader.no_message("/late/attitude", "geometry_msgs/msg/QuaternionStamped", 5))
    finally:
        pub_side.close()
        reader.close()
