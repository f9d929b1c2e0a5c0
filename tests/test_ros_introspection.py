"""Graph introspection on the Cyclone DDS path, read by independent means.

- RIHS01 type hashes (rosbags' ``hash_rihs01``) equal the values ROS 2 Jazzy's rosidl computes;
- every writer and reader carries ``typehash=…;`` in its USER_DATA, the participant ``enclave=/;``,
  read from the DDS built-in topics (what any DDS tool and every rmw implementation read);
- ``ros_discovery_info`` holds the node's name, namespace and the GIDs of exactly its readers and
  writers (the GUIDs the built-in topics report), transient local for late joiners, and an empty node
  list when the node goes, as rmw_cyclonedds publishes it.
"""
from __future__ import annotations

import time

import pytest
from cyclonedds.builtin import (
    BuiltinDataReader,
    BuiltinTopicDcpsParticipant,
    BuiltinTopicDcpsPublication,
    BuiltinTopicDcpsSubscription,
)
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from moose_ros.interfaces import message_class, type_hash
from moose_ros.runtime import QOS_SENSOR, DdsNode
from moose_ros.runtime.dds import DISCOVERY_TOPIC, DISCOVERY_TYPE

JAZZY_HASHES = {
    # what ROS 2 Jazzy's rosidl writes into share/<pkg>/msg/<Type>.json and rmw puts on the wire
    # (REP-2011); the same values are asserted live against rclpy's own publishers in tests/test_rclpy_graph.py
    "nav_msgs/msg/Odometry": "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    "sensor_msgs/msg/Imu": "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b",
    "rosgraph_msgs/msg/Clock": "RIHS01_692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564",
    "tf2_msgs/msg/TFMessage": "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
    "std_msgs/msg/Header": "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01",
}


@pytest.mark.parametrize("type_name", sorted(JAZZY_HASHES))
def test_type_hash_is_ros2_jazzys(type_name: str) -> None:
    assert type_hash(type_name) == JAZZY_HASHES[type_name]


def test_type_hash_of_our_messages_is_well_formed_and_distinct() -> None:
    hashes = {type_hash(f"moose_msgs/msg/{n}") for n in ("Threat", "Blend", "PlannerOutput", "StateEstimate")}
    assert len(hashes) == 4 and all(h.startswith("RIHS01_") and len(h) == 71 for h in hashes)


def _wait(predicate, limit: float = 10.0):  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    return predicate()


@pytest.mark.graph
def test_discovery_info_and_user_data_seen_from_outside() -> None:
    import os

    domain = int(os.environ["ROS_DOMAIN_ID"])
    node = DdsNode("talker", namespace="/car1")
    pub = node.publisher("nav_msgs/msg/Odometry", "/vehicle/odom", QOS_SENSOR)
    node.subscription("sensor_msgs/msg/Imu", "imu", lambda m: None)
    own, own_gid = str(node.participant.guid), node.participant.guid.bytes
    # an outside observer joins late: transient local must hand it the last graph message
    outside = DomainParticipant(domain)
    try:
        topic = Topic(outside, DISCOVERY_TOPIC, message_class(DISCOVERY_TYPE))
        reader = DataReader(outside, topic, qos=Qos(Policy.Reliability.Reliable(duration(seconds=1)),
                                                    Policy.Durability.TransientLocal, Policy.History.KeepLast(1)))
        pubs = BuiltinDataReader(outside, BuiltinTopicDcpsPublication)
        subs = BuiltinDataReader(outside, BuiltinTopicDcpsSubscription)
        parts = BuiltinDataReader(outside, BuiltinTopicDcpsParticipant)

        def ours(builtin):  # type: ignore[no-untyped-def]
            return [e for e in builtin.read(N=256) if str(e.participant_key) == own]

        writers = _wait(lambda: [e for e in ours(pubs) if e.topic_name == "rt/vehicle/odom"])
        readers = _wait(lambda: [e for e in ours(subs) if e.topic_name == "rt/car1/imu"])
        assert writers and readers
        assert writers[0].qos[Policy.Userdata].data == f"typehash={JAZZY_HASHES['nav_msgs/msg/Odometry']};".encode()
        assert readers[0].qos[Policy.Userdata].data == f"typehash={type_hash('sensor_msgs/msg/Imu')};".encode()
        graph_writer = [e for e in ours(pubs) if e.topic_name == DISCOVERY_TOPIC][0]
        assert graph_writer.type_name == "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"
        assert graph_writer.qos[Policy.Durability] == Policy.Durability.TransientLocal
        assert graph_writer.qos[Policy.Userdata].data == f"typehash={type_hash(DISCOVERY_TYPE)};".encode()
        participant = _wait(lambda: [p for p in parts.read(N=256) if str(p.key) == own])
        assert participant[0].qos[Policy.Userdata].data == b"enclave=/;"

        samples = _wait(lambda: [s for s in reader.read(N=16) if bytes(s.gid.data) == own_gid])
        info = samples[-1]
        assert [(n.node_namespace, n.node_name) for n in info.node_entities_info_seq] == [("/car1", "talker")]
        entities = info.node_entities_info_seq[0]
        assert [bytes(g.data) for g in entities.writer_gid_seq] == [writers[0].key.bytes]
        assert [bytes(g.data) for g in entities.reader_gid_seq] == [readers[0].key.bytes]
        del pub
        node.shutdown()  # the node goes: its participant announces an empty node list first
        gone = _wait(lambda: [s for s in reader.read(N=16) if bytes(s.gid.data) == own_gid
                              and not s.node_entities_info_seq], limit=5.0)
        assert gone
    finally:
        node.shutdown()
        outside.__del__()
