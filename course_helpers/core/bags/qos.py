"""The QoS a bag keeps for each topic, and the two rules rosbag2 (Jazzy) applies to it.

rosbag2 stores, for every topic, the QoS profiles its publishers *offered* when the recorder
subscribed (``offered_qos_profiles`` in ``metadata.yaml``: one profile per publisher, as the
graph reports it, so the history shows as ``unknown`` and the depth as 0). Two rules of
``rosbag2_storage/src/rosbag2_storage/qos.cpp`` use them, and this module follows both:

* :func:`request_for_offers` (``Rosbag2QoS::adapt_request_to_offers``): the recorder subscribes
  RELIABLE only if every publisher offers it, TRANSIENT_LOCAL only if every publisher does, so it
  connects to all of them; history KEEP_LAST 10, nothing else set;
* :func:`offer_for_playback` (``Rosbag2QoS::adapt_offer_to_recorded_offers``): the player offers
  the recorded profile when all publishers offered the same one (history and lifespan aside),
  with history KEEP_LAST 10; otherwise rosbag2's default (KEEP_LAST 10, RELIABLE, VOLATILE).

A transient-local topic is therefore replayed as transient-local, and a late subscriber still
gets its last message.
"""

from __future__ import annotations

from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

DEFAULT_DEPTH = 10  # rmw_qos_profile_default.depth: rosbag2's history for recording and playback
INFINITE_NS = 9223372036 * 10**9 + 854775807  # RMW_DURATION_INFINITE, as the graph reports "not set"


def _time(duration: Duration) -> QosTime:
    sec, nsec = divmod(duration.nanoseconds, 10**9)
    return QosTime(sec, nsec)


def _duration(value: QosTime) -> Duration:
    return Duration(nanoseconds=value.sec * 10**9 + value.nsec)


def to_bag_qos(profile: QoSProfile) -> Qos:
    """An rclpy profile (as the graph reports a publisher's offer) in the bag's form."""
    return Qos(QosHistory[profile.history.name], profile.depth, QosReliability[profile.reliability.name],
               QosDurability[profile.durability.name], _time(profile.deadline), _time(profile.lifespan),
               QosLiveliness[profile.liveliness.name], _time(profile.liveliness_lease_duration),
               bool(profile.avoid_ros_namespace_conventions))


def from_bag_qos(qos: Qos) -> QoSProfile:
    """A profile read from a bag as an rclpy QoSProfile (history as recorded: often unknown)."""
    history = HistoryPolicy[qos.history.name]
    profile = QoSProfile(history=history if history != HistoryPolicy.UNKNOWN else HistoryPolicy.KEEP_LAST,
                         depth=qos.depth or DEFAULT_DEPTH)
    profile.reliability = ReliabilityPolicy[qos.reliability.name]
    profile.durability = DurabilityPolicy[qos.durability.name]
    profile.liveliness = LivelinessPolicy[qos.liveliness.name]
    profile.deadline = _duration(qos.deadline)
    profile.lifespan = _duration(qos.lifespan)
    profile.liveliness_lease_duration = _duration(qos.liveliness_lease_duration)
    profile.avoid_ros_namespace_conventions = qos.avoid_ros_namespace_conventions
    return profile


def request_for_offers(offers: list[QoSProfile]) -> QoSProfile:
    """The recorder's subscription QoS for a topic whose publishers offer ``offers``."""
    request = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEFAULT_DEPTH)
    if not offers:
        return request
    reliable = all(p.reliability == ReliabilityPolicy.RELIABLE for p in offers)
    latched = all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in offers)
    request.reliability = ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT
    request.durability = DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE
    return request


def _compatibility(qos: Qos) -> tuple:
    """What rosbag2 compares between offers: everything but history and lifespan."""
    return (qos.reliability, qos.durability, qos.deadline, qos.liveliness, qos.liveliness_lease_duration)


def offer_for_playback(recorded: list[Qos]) -> QoSProfile:
    """The player's publisher QoS for a topic recorded with the offers ``recorded``."""
    if recorded and all(_compatibility(q) == _compatibility(recorded[0]) for q in recorded):
        profile = from_bag_qos(recorded[0])
        profile.history, profile.depth = HistoryPolicy.KEEP_LAST, DEFAULT_DEPTH
        return profile
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEFAULT_DEPTH)


def describe(qos: Qos) -> str:
    """One line: 'reliable, transient_local, deadline 0.5 s' (durations shown only when set)."""
    parts = [qos.reliability.name.lower(), qos.durability.name.lower()]
    if qos.history not in (QosHistory.UNKNOWN, QosHistory.SYSTEM_DEFAULT):
        parts.insert(0, f"{qos.history.name.lower()} {qos.depth}")
    for name, value in (("deadline", qos.deadline), ("lifespan", qos.lifespan),
                        ("lease", qos.liveliness_lease_duration)):
        ns = value.sec * 10**9 + value.nsec
        if 0 < ns < INFINITE_NS:
            parts.append(f"{name} {ns / 1e9:g} s")
    return ", ".join(parts)
