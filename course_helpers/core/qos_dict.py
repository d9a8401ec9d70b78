"""QoS profiles as plain dicts, so they cross process boundaries as JSON (chapters 08, 08b, 10).

``qos_from_dict({'reliability': 'best_effort', 'depth': 5, 'deadline_s': 0.2})`` builds a
``QoSProfile``; ``qos_to_dict`` is its inverse; ``describe_qos`` prints a one-line summary.
Durations are seconds, and 0 means "not set" (infinite).
"""

from __future__ import annotations

from rclpy.duration import Duration
from rclpy.qos import (
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSLivelinessPolicy,
    QoSProfile,
    QoSReliabilityPolicy,
)

from course_helpers.core.errors import CourseError

_RELIABILITY = {"reliable": QoSReliabilityPolicy.RELIABLE, "best_effort": QoSReliabilityPolicy.BEST_EFFORT,
                "system_default": QoSReliabilityPolicy.SYSTEM_DEFAULT}
_DURABILITY = {"volatile": QoSDurabilityPolicy.VOLATILE,
               "transient_local": QoSDurabilityPolicy.TRANSIENT_LOCAL,
               "system_default": QoSDurabilityPolicy.SYSTEM_DEFAULT}
_HISTORY = {"keep_last": QoSHistoryPolicy.KEEP_LAST, "keep_all": QoSHistoryPolicy.KEEP_ALL,
            "system_default": QoSHistoryPolicy.SYSTEM_DEFAULT}
_LIVELINESS = {"automatic": QoSLivelinessPolicy.AUTOMATIC,
               "manual_by_topic": QoSLivelinessPolicy.MANUAL_BY_TOPIC,
               "system_default": QoSLivelinessPolicy.SYSTEM_DEFAULT}
DEFAULT_QOS_DICT = {"history": "keep_last", "depth": 10, "reliability": "reliable",
                    "durability": "volatile", "deadline_s": 0.0, "lifespan_s": 0.0,
                    "liveliness": "automatic", "lease_s": 0.0}


def duration_seconds(duration: Duration) -> float:
    """A QoS duration in seconds; 0.0 means 'not set' (infinite)."""
    ns = duration.nanoseconds
    return 0.0 if ns <= 0 or ns >= 2**62 else ns / 1e9


def seconds_to_duration(seconds: float, what: str) -> Duration:
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or seconds < 0:
        raise CourseError(f"{what} must be a number of seconds >= 0 (0 means infinite), got {seconds!r}")
    return Duration(nanoseconds=int(round(seconds * 1e9)))


def _pick(table: dict, value: str, what: str):
    if value not in table:
        raise CourseError(f"{what} must be one of {', '.join(table)}, got {value!r}")
    return table[value]


def qos_from_dict(values: dict) -> QoSProfile:
    """A ``QoSProfile`` from a dict like ``{'reliability': 'best_effort', 'depth': 5, 'deadline_s': 0.2}``.

    Keys (all optional): history, depth, reliability, durability, deadline_s, lifespan_s,
    liveliness, lease_s. Durations are seconds; 0 means infinite (not set).
    """
    if not isinstance(values, dict):
        raise CourseError(f"a QoS dict is needed, got {type(values).__name__}")
    unknown = set(values) - set(DEFAULT_QOS_DICT)
    if unknown:
        raise CourseError(f"unknown QoS key(s) {sorted(unknown)}; allowed: {', '.join(DEFAULT_QOS_DICT)}")
    v = {**DEFAULT_QOS_DICT, **values}
    history = _pick(_HISTORY, v["history"], "history")
    depth = v["depth"]
    if history == QoSHistoryPolicy.KEEP_LAST and (isinstance(depth, bool) or not isinstance(depth, int)
                                                   or depth < 1):
        raise CourseError(f"depth must be a whole number >= 1 with keep_last, got {depth!r}")
    profile = QoSProfile(history=history, depth=depth if history == QoSHistoryPolicy.KEEP_LAST else 1,
                         reliability=_pick(_RELIABILITY, v["reliability"], "reliability"),
                         durability=_pick(_DURABILITY, v["durability"], "durability"),
                         liveliness=_pick(_LIVELINESS, v["liveliness"], "liveliness"))
    if v["deadline_s"]:
        profile.deadline = seconds_to_duration(v["deadline_s"], "deadline_s")
    if v["lifespan_s"]:
        profile.lifespan = seconds_to_duration(v["lifespan_s"], "lifespan_s")
    if v["lease_s"]:
        profile.liveliness_lease_duration = seconds_to_duration(v["lease_s"], "lease_s")
    return profile


def qos_to_dict(profile: QoSProfile) -> dict:
    """The inverse of :func:`qos_from_dict` (JSON-friendly, for child processes)."""
    def name(table, value):
        return next(k for k, v in table.items() if v == value)

    return {"history": name(_HISTORY, profile.history), "depth": profile.depth,
            "reliability": name(_RELIABILITY, profile.reliability),
            "durability": name(_DURABILITY, profile.durability),
            "deadline_s": duration_seconds(profile.deadline),
            "lifespan_s": duration_seconds(profile.lifespan),
            "liveliness": name(_LIVELINESS, profile.liveliness),
            "lease_s": duration_seconds(profile.liveliness_lease_duration)}


def policy_name(policy) -> str:
    return policy.name if hasattr(policy, "name") else str(policy)


def describe_qos(profile: QoSProfile) -> str:
    """A one-line summary such as 'RELIABLE, VOLATILE, KEEP_LAST(10), deadline 0.2 s'."""
    history = (f"KEEP_LAST({profile.depth})" if profile.history == QoSHistoryPolicy.KEEP_LAST
               else policy_name(profile.history))
    parts = [policy_name(profile.reliability), policy_name(profile.durability), history]
    for label, value in (("deadline", profile.deadline), ("lifespan", profile.lifespan),
                         ("lease", profile.liveliness_lease_duration)):
        if duration_seconds(value):
            parts.append(f"{label} {duration_seconds(value):g} s")
    if profile.liveliness == QoSLivelinessPolicy.MANUAL_BY_TOPIC:
        parts.append("MANUAL_BY_TOPIC")
    return ", ".join(parts)
