"""rclpy's predefined QoS profiles side by side."""

from __future__ import annotations

from rclpy.qos import QoSHistoryPolicy

from course_helpers.core.qos_dict import policy_name

PREDEFINED = [
    ("qos_profile_default", "publishers and subscriptions unless told otherwise"),
    ("qos_profile_sensor_data", "sensor streams: the newest sample matters, old ones do not"),
    ("qos_profile_services_default", "service requests and replies"),
    ("qos_profile_parameters", "parameter services"),
    ("qos_profile_parameter_events", "/parameter_events"),
    ("qos_profile_action_status_default", "an action's status topic (late joiners get the state)"),
    ("qos_profile_system_default", "whatever the middleware's own defaults are"),
    ("qos_profile_best_available", "subscriptions that adapt to the publishers they find"),
]


def _duration_cell(value) -> str:
    ns = value.nanoseconds
    if ns in (0, 2**63 - 1):
        return "infinite"
    return "best available" if ns >= 2**62 else f"{ns / 1e9:g} s"


def profiles_table() -> list[dict]:
    """One dict per predefined rclpy profile: its name, its policies as text, and what it is used for."""
    from rclpy import qos as rq

    rows = []
    for name, use in PREDEFINED:
        profile = getattr(rq, name)
        history = policy_name(profile.history)
        if profile.history == QoSHistoryPolicy.KEEP_LAST:
            history = f"KEEP_LAST({profile.depth})"
        rows.append({"profile": name, "reliability": policy_name(profile.reliability),
                     "durability": policy_name(profile.durability), "history": history,
                     "deadline": _duration_cell(profile.deadline),
                     "liveliness": policy_name(profile.liveliness), "used for": use})
    return rows


def show_profiles_table(rows: list[dict] | None = None) -> None:
    """Print ``rows`` (by default :func:`profiles_table`) aligned, then what each profile is for."""
    rows = rows or profiles_table()
    keys = ["profile", "reliability", "durability", "history", "deadline", "liveliness"]
    widths = {k: max(len(k), *(len(str(r[k])) for r in rows)) for k in keys}
    print("  ".join(f"{k:<{widths[k]}}" for k in keys))
    for r in rows:
        print("  ".join(f"{r[k]:<{widths[k]}}" for k in keys))
    print()
    for r in rows:
        print(f"{r['profile']:<{widths['profile']}}  {r['used for']}")
