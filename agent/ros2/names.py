"""Zenoh key expressions of ROS 2 topics, in both conventions, and rmw_zenoh's liveliness tokens (pure).

``rmw_zenoh`` (ROS 2 nodes run with ``RMW_IMPLEMENTATION=rmw_zenoh_cpp``; its design notes,
"Topic and Service name mapping to Zenoh key expressions" and "Graph Cache"):

* a topic's key is ``<domain_id>/<fully qualified name without its leading />/<DDS type
  name>/<type hash>``, e.g. ``0/chatter/std_msgs::msg::dds_::String_/RIHS01_df66…``; the
  DDS type name of ``pkg/msg/Name`` is ``pkg::msg::dds_::Name_``; the type hash is the
  REP-2016 ``RIHS01_`` hash of the message definition (:mod:`agent.ros2.messages` takes it
  from ``rosbags``);
* every node, publisher and subscription declares a liveliness token
  ``@ros2_lv/<domain>/<session id>/<node id>/<entity id>/<kind>/<enclave>/<namespace>/<node>``
  (kind ``NN`` for a node, with ``<entity id>`` = ``<node id>``), followed for a publisher
  (``MP``) or subscription (``MS``) by ``/<topic>/<DDS type name>/<type hash>/<qos>``; names
  are *mangled* (every ``/`` → ``%``; the root namespace and the default enclave ``/`` are
  ``%``); ``<qos>`` is rmw_zenoh's compact form, empty fields meaning the default
  (:data:`DEFAULT_QOS`: reliable, volatile, keep last, the default depth).

``zenoh-bridge-ros2dds`` (the bridge beside ordinary DDS nodes): the key is the topic name
without its leading ``/`` (``scan``, ``robot1/odom``), optionally below the bridge's own
``--namespace``; no liveliness tokens of ours.
"""

from __future__ import annotations

import re

ADMIN_SPACE = "@ros2_lv"
NODE, PUBLISHER, SUBSCRIPTION = "NN", "MP", "MS"
#: rmw_zenoh's QoS chunk with every field at its default.
DEFAULT_QOS = "::,:,:,:,,"

_TYPE = re.compile(r"([A-Za-z0-9_]+)/(msg|srv)/([A-Za-z0-9_]+)")


def dds_type_name(ros_type: str) -> str:
    """``"sensor_msgs/msg/LaserScan"`` → ``"sensor_msgs::msg::dds_::LaserScan_"``.

    Raises:
        ValueError: not a ``pkg/msg/Name`` type name.
    """
    m = _TYPE.fullmatch(ros_type)
    if not m:
        raise ValueError(f"expected a ROS 2 type name like sensor_msgs/msg/LaserScan, got {ros_type!r}")
    pkg, kind, name = m.groups()
    return f"{pkg}::{kind}::dds_::{name}_"


def qualified(topic: str, namespace: str = "") -> str:
    """The fully qualified name of ``topic``: absolute names as they are, relative ones below
    ``namespace`` (``"scan"`` in ``/robot1`` → ``/robot1/scan``)."""
    if topic.startswith("/"):
        return "/" + topic.strip("/")
    ns = namespace.strip("/")
    return "/" + (f"{ns}/" if ns else "") + topic.strip("/")


def mangle(name: str) -> str:
    """rmw_zenoh's mangling: every ``/`` becomes ``%``."""
    return name.replace("/", "%")


def rmw_zenoh_key(domain: int, topic: str, ros_type: str, type_hash: str) -> str:
    """The rmw_zenoh key of a fully qualified ``topic`` of ``ros_type`` with ``type_hash``."""
    return f"{int(domain)}/{topic.strip('/')}/{dds_type_name(ros_type)}/{type_hash}"


def bridge_key(topic: str, bridge_namespace: str = "") -> str:
    """The zenoh-bridge-ros2dds key of a fully qualified ``topic``."""
    ns = bridge_namespace.strip("/")
    return (f"{ns}/" if ns else "") + topic.strip("/")


def node_token(
    domain: int, session_id: str, node_id: int, node: str, namespace: str = "/", enclave: str = "/"
) -> str:
    """The liveliness token of a node."""
    ns = "/" + namespace.strip("/") if namespace.strip("/") else "/"
    return "/".join(
        (
            ADMIN_SPACE,
            str(int(domain)),
            session_id,
            str(node_id),
            str(node_id),
            NODE,
            mangle(enclave),
            mangle(ns),
            node,
        )
    )


def entity_token(
    domain: int,
    session_id: str,
    node_id: int,
    entity_id: int,
    kind: str,
    node: str,
    topic: str,
    ros_type: str,
    type_hash: str,
    *,
    namespace: str = "/",
    enclave: str = "/",
    qos: str = DEFAULT_QOS,
) -> str:
    """The liveliness token of a publisher (``MP``) or subscription (``MS``) of a node."""
    if kind not in (PUBLISHER, SUBSCRIPTION):
        raise ValueError(f"kind must be {PUBLISHER!r} or {SUBSCRIPTION!r}, got {kind!r}")
    ns = "/" + namespace.strip("/") if namespace.strip("/") else "/"
    return "/".join(
        (
            ADMIN_SPACE,
            str(int(domain)),
            session_id,
            str(node_id),
            str(entity_id),
            kind,
            mangle(enclave),
            mangle(ns),
            node,
            mangle(topic),
            dds_type_name(ros_type),
            type_hash,
            qos,
        )
    )
