"""Whether a publisher and a subscription connect, policy by policy.

:func:`explain_compatibility` applies the DDS 'requested vs offered' rule to each policy;
:func:`rclpy_verdict` asks rclpy's own ``qos_check_compatible``; :func:`try_pair` creates a real
pair and records what arrived and the incompatible-QoS events at both ends.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.qos import QoSCompatibility, QoSProfile, qos_check_compatible, qos_policy_name_from_kind
from std_msgs.msg import String

from course_helpers.chapters.ch08_qos.cleanup import remove_nodes
from course_helpers.core.qos_dict import qos_to_dict
from course_helpers.core.waiting import poll_until

PAIR_PERIOD_S = 0.05  # s between the live pair's messages
PAIR_ENOUGH = 3  # messages that prove a live pair connects
LATE_JOIN_S = 0.3  # s between the publisher's messages and a late joiner's subscription
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
             msg_type=String, make_message: Callable | None = None,
             published_before: int | None = None, until_all_stored: bool = False) -> PairResult:
    """Create a real publisher (profile ``pub``) and subscription (``sub``) on ``topic``; watch them.

    Args:
        rt: the kernel's runtime (both nodes run in it).
        pub, sub: the two profiles.
        seconds: the longest watch.
        topic, msg_type: the topic and its message class.
        make_message: builds each message (default ``msg_type()``).
        published_before: if given, the publisher sends this many messages once, before the
            subscription exists, and then stays silent (the subscription joins late and is
            watched for the whole ``seconds``, or, with ``until_all_stored``, until every one of them
            arrived). Otherwise it publishes every 50 ms and the watch ends as soon as 3 messages
            arrived or both ends reported an incompatibility. A watch that ends early is no window:
            ``seconds`` then only bounds a hang.

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
    if published_before is None:
        pub_node.create_timer(PAIR_PERIOD_S, lambda: publisher.publish(make_message()))
    else:
        for _ in range(published_before):
            publisher.publish(make_message())
        time.sleep(LATE_JOIN_S)  # published well before the subscription exists
    sub_node = rt.node("qos_pair_sub", console=False)
    sub_node.create_subscription(
        msg_type, topic, received.append, sub,
        event_callbacks=SubscriptionEventCallbacks(
            incompatible_qos=lambda s: sub_events.append(_policy_of(s))))

    def settled() -> bool:
        if pub_events and sub_events:
            return True
        if published_before is None:
            return len(received) >= PAIR_ENOUGH
        return until_all_stored and len(received) >= published_before

    try:
        poll_until(settled, seconds)
    finally:
        remove_nodes(rt, pub_node, sub_node)
    return PairResult(len(received), sorted(set(pub_events)), sorted(set(sub_events)))


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
