"""Whether a publisher and a subscription connect, policy by policy.

:func:`explain_compatibility` applies the DDS 'requested vs offered' rule to each policy;
:func:`rclpy_verdict` asks rclpy's own ``qos_check_compatible``; :func:`try_pair` creates a real
pair and records what arrived and the incompatible-QoS events at both ends; :func:`late_joiner_gets`
counts what a reliable subscription that joins late gets of what was published before it.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass

from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.qos import (
    QoSCompatibility,
    QoSHistoryPolicy,
    QoSProfile,
    QoSReliabilityPolicy,
    qos_check_compatible,
    qos_policy_name_from_kind,
)
from std_msgs.msg import String

from course_helpers.chapters.ch08_qos.cleanup import remove_nodes
from course_helpers.core.errors import CourseError
from course_helpers.core.qos_dict import qos_to_dict
from course_helpers.core.waiting import HANG_S, poll_until

PAIR_PERIOD_S = 0.05  # s between the live pair's messages
PAIR_ENOUGH = 3  # messages that prove a live pair connects
AT_LEAST = "the publisher offers at least what is requested"


@dataclass
class PolicyVerdict:
    """Whether one policy lets the publisher and subscription match, and why."""

    policy: str
    publisher: str
    subscription: str
    compatible: bool | None  # None: this policy plays no part in matching
    reason: str


def _duration_text(seconds: float) -> str:
    return "infinite" if not seconds else f"{seconds:g} s"


def _history_text(values: dict) -> str:
    history = values["history"]
    return f"{history}({values['depth']})" if history == "keep_last" else history


def _no_longer(offered_s: float, requested_s: float) -> bool:
    """A promised period (deadline, lease) satisfies a request if the request is infinite or the
    promise is no longer."""
    return not requested_s or (bool(offered_s) and offered_s <= requested_s)


def _rule(policy: str, offered: str, requested: str, ok: bool, fine: str, wrong: str) -> PolicyVerdict:
    return PolicyVerdict(policy, offered, requested, ok, fine if ok else wrong)


def explain_compatibility(pub: QoSProfile, sub: QoSProfile) -> list[PolicyVerdict]:
    """One :class:`PolicyVerdict` per policy for publisher profile ``pub`` and subscription profile ``sub``.

    The DDS 'requested vs offered' rule: the publisher must offer at least what the subscription
    requests. History, depth and lifespan never prevent a match.
    """
    p, s = qos_to_dict(pub), qos_to_dict(sub)
    reliable = not (p["reliability"] == "best_effort" and s["reliability"] == "reliable")
    durable = not (p["durability"] == "volatile" and s["durability"] == "transient_local")
    lively = not (p["liveliness"] == "automatic" and s["liveliness"] == "manual_by_topic")
    return [
        _rule("reliability", p["reliability"], s["reliability"], reliable, AT_LEAST,
              "a best-effort publisher cannot promise the delivery a reliable subscription requests"),
        _rule("durability", p["durability"], s["durability"], durable, AT_LEAST,
              "a volatile publisher keeps nothing for late joiners, which a transient-local subscription "
              "requests"),
        _rule("deadline", _duration_text(p["deadline_s"]), _duration_text(s["deadline_s"]),
              _no_longer(p["deadline_s"], s["deadline_s"]),
              "the publisher promises a period no longer than the one requested",
              "the subscription requests a shorter period than the publisher promises"),
        _rule("liveliness", p["liveliness"], s["liveliness"], lively,
              "the publisher's kind is at least as strict as requested",
              "manual-by-topic is requested but the publisher only offers automatic liveliness"),
        _rule("lease duration", _duration_text(p["lease_s"]), _duration_text(s["lease_s"]),
              _no_longer(p["lease_s"], s["lease_s"]),
              "the publisher promises to assert within the requested lease",
              "the subscription requests a shorter lease than the publisher promises"),
        PolicyVerdict("history / depth", _history_text(p), _history_text(s), None,
                      "local to each side: never prevents a match"),
        PolicyVerdict("lifespan", _duration_text(p["lifespan_s"]), _duration_text(s["lifespan_s"]), None,
                      "a publisher-side setting: never prevents a match"),
    ]


def compatible(pub: QoSProfile, sub: QoSProfile) -> bool:
    """True if every policy in :func:`explain_compatibility` allows the match."""
    return all(row.compatible is not False for row in explain_compatibility(pub, sub))


def rclpy_verdict(pub: QoSProfile, sub: QoSProfile) -> tuple[str, str]:
    """rclpy's own check, ``qos_check_compatible``: ('OK' | 'WARNING' | 'ERROR', reason)."""
    verdict, reason = qos_check_compatible(pub, sub)
    return QoSCompatibility(verdict).name, reason


@dataclass
class PairResult:
    """What a live publisher/subscription pair did."""

    received: int  # messages the subscription got
    publisher_events: list[str]  # incompatible-QoS events at the publisher (policy names)
    subscription_events: list[str]

    @property
    def connected(self) -> bool:
        """True if any message arrived."""
        return self.received > 0


def _policy_of(status) -> str:
    return qos_policy_name_from_kind(status.last_policy_kind)


def try_pair(rt, pub: QoSProfile, sub: QoSProfile, seconds: float = 1.0, topic: str = "qos_pair",
             msg_type=String, make_message: Callable | None = None) -> PairResult:
    """Create a real publisher (profile ``pub``) and subscription (``sub``) on ``topic``; watch them.

    The publisher sends a message every 50 ms. The watch ends as soon as 3 messages arrived or both
    ends reported an incompatibility, or after ``seconds`` (for a pair that does neither).

    Args:
        rt: the kernel's runtime (both nodes run in it).
        pub, sub: the two profiles.
        seconds: the longest watch.
        topic, msg_type: the topic and its message class.
        make_message: builds each message (default ``msg_type()``).

    Returns a :class:`PairResult`.
    """
    make_message = make_message or msg_type
    received: list = []
    pub_events: list[str] = []
    sub_events: list[str] = []
    pub_node = rt.node("qos_pair_pub", console=False)
    publisher = pub_node.create_publisher(
        msg_type, topic, pub,
        event_callbacks=PublisherEventCallbacks(incompatible_qos=lambda s: pub_events.append(_policy_of(s))))
    pub_node.create_timer(PAIR_PERIOD_S, lambda: publisher.publish(make_message()))
    sub_node = rt.node("qos_pair_sub", console=False)
    sub_node.create_subscription(
        msg_type, topic, received.append, sub,
        event_callbacks=SubscriptionEventCallbacks(
            incompatible_qos=lambda s: sub_events.append(_policy_of(s))))
    try:
        poll_until(lambda: bool(pub_events and sub_events) or len(received) >= PAIR_ENOUGH, seconds)
    finally:
        remove_nodes(rt, pub_node, sub_node)
    return PairResult(len(received), sorted(set(pub_events)), sorted(set(sub_events)))


def late_joiner_gets(rt, qos: QoSProfile, published: list, sentinel, topic: str = "late_joiner") -> int:
    """How many of ``published`` the publisher hands a subscription that joins after they were sent.

    Both ends use ``qos``, except that the late joiner queues everything it is handed (KEEP_ALL:
    history is local to each side and never changes a match), so that its own queue drops none of
    them before they are counted. Holds by construction, with no window: the subscription joins;
    once the publisher has matched it, DDS's acknowledgements say the subscription holds everything
    it will ever get of the earlier messages; then ``sentinel`` (a message unlike those) is sent, and
    a reliable subscription takes messages in order, so what came before the sentinel is the answer.
    Only a RELIABLE profile promises that order: a best-effort one raises :class:`CourseError`.
    """
    if qos.reliability != QoSReliabilityPolicy.RELIABLE:
        raise CourseError("only a RELIABLE pair says for certain what a late joiner gets: best effort "
                          "promises no delivery")
    received: list = []
    pub_node = rt.node("late_joiner_pub", console=False)
    publisher = pub_node.create_publisher(type(sentinel), topic, qos)
    for message in published:
        publisher.publish(message)
    sub_node = rt.node("late_joiner", console=False)
    queue_all = copy.copy(qos)
    queue_all.history = QoSHistoryPolicy.KEEP_ALL
    sub_node.create_subscription(type(sentinel), topic, received.append, queue_all)
    try:
        rt.wait_until(lambda: publisher.get_subscription_count() > 0, what="the late joiner to match")
        if not publisher.wait_for_all_acked(Duration(seconds=HANG_S)):
            raise CourseError(f"the late joiner acknowledged nothing within {HANG_S:g} s (a hang)")
        publisher.publish(sentinel)
        rt.wait_until(lambda: sentinel in received, what="the sentinel at the late joiner")
    finally:
        remove_nodes(rt, pub_node, sub_node)
    return received.index(sentinel)  # the messages that came before it


def compatibility_report(rt, pub: QoSProfile, sub: QoSProfile, live: bool = True) -> str:
    """Text: the per-policy table, rclpy's verdict and (if ``live``) what a real pair did."""
    rows = explain_compatibility(pub, sub)
    lines = [f"{'policy':<16} {'publisher':<16} {'subscription':<16} verdict",
             "-" * 72]
    for r in rows:
        mark = "n/a" if r.compatible is None else ("ok" if r.compatible else "MISMATCH")
        lines.append(f"{r.policy:<16} {r.publisher:<16} {r.subscription:<16} {mark}: {r.reason}")
    expected = compatible(pub, sub)
    verdict, reason = rclpy_verdict(pub, sub)
    lines.append("")
    lines.append(f"prediction: {'they connect' if expected else 'they do NOT connect'}")
    lines.append(f"rclpy.qos.qos_check_compatible: {verdict}" + (f" ({reason.strip()})" if reason else ""))
    if live:
        pair = try_pair(rt, pub, sub)
        events = ", ".join(pair.subscription_events) or "none"
        lines.append(f"live pair: {'messages arrived' if pair.connected else 'no message arrived'}; "
                     f"incompatible-QoS events at the subscription: {events}")
    return "\n".join(lines)
