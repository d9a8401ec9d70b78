"""Checker of chapter 07's exercise: keep two teams apart on one machine (domains and discovery range).

The student writes ``plan(kernel_domain, spare_domain) -> {role: env}``: the extra environment
variables for four child-process nodes. The checker starts them for real and looks at who can see
and hear whom.
"""

from __future__ import annotations

import time

from course_helpers.chapters.ch07_dds import ReportingListener, heard_lines
from course_helpers.checks import CheckReport
from course_helpers.core.domains import reserve_spare_domain
from course_helpers.core.names import as_full_name
from course_helpers.core.waiting import poll_until
from course_helpers.nodes import Talker

ROLES = ("talker", "listener", "monitor", "loner")
ALLOWED_VARIABLES = ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")
ALLOWED_RANGES = ("OFF", "LOCALHOST", "SUBNET", "SYSTEM_DEFAULT")
UNWANTED_VISIBILITY_WAIT_S = 4.5
_NODES = {"talker": "team_talker", "listener": "team_listener", "monitor": "monitor", "loner": "loner"}
# role -> (child-process target, its arguments besides the node name); each node names its process
_TARGETS = {"talker": (Talker, {"topic": "team_chatter", "rate_hz": 10.0}),
            "listener": (ReportingListener, {"topic": "team_chatter"}),
            "monitor": (Talker, {"topic": "monitor_status", "rate_hz": 1.0}),
            "loner": (Talker, {"topic": "loner_chatter", "rate_hz": 1.0})}


def _validate(plan_result, kernel_domain: int, spare_domain: int) -> list[str]:
    if not isinstance(plan_result, dict):
        return [f"plan() must return a dict of role -> environment dict, got {type(plan_result).__name__}"]
    problems = []
    missing = [r for r in ROLES if r not in plan_result]
    extra = [r for r in plan_result if r not in ROLES]
    if missing:
        problems.append(f"missing role(s): {', '.join(missing)}")
    if extra:
        problems.append(f"unknown role(s): {', '.join(map(str, extra))}; the roles are {', '.join(ROLES)}")
    for role in ROLES:
        env = plan_result.get(role, {})
        if not isinstance(env, dict):
            problems.append(f"{role}: the environment must be a dict, got {type(env).__name__}")
            continue
        for key, value in env.items():
            if key not in ALLOWED_VARIABLES:
                problems.append(f"{role}: {key} is not allowed here (use {', '.join(ALLOWED_VARIABLES)})")
            elif key == "ROS_DOMAIN_ID" and str(value) not in (str(kernel_domain), str(spare_domain)):
                problems.append(f"{role}: ROS_DOMAIN_ID={value!r}; use the kernel's domain ({kernel_domain}) "
                                f"or the spare one reserved for you ({spare_domain}), so no other kernel is "
                                "disturbed")
            elif key == "ROS_AUTOMATIC_DISCOVERY_RANGE" and str(value).upper() not in ALLOWED_RANGES:
                problems.append(f"{role}: ROS_AUTOMATIC_DISCOVERY_RANGE={value!r}; "
                                f"allowed: {', '.join(ALLOWED_RANGES)}")
            elif key == "ROS_AUTOMATIC_DISCOVERY_RANGE" and str(value).upper() == "SUBNET":
                problems.append(f"{role}: SUBNET would announce the node to the whole network; keep it "
                                "on this machine")
    loner_domain = str(plan_result.get("loner", {}).get("ROS_DOMAIN_ID", kernel_domain)) \
        if isinstance(plan_result.get("loner"), dict) else str(kernel_domain)
    if loner_domain != str(kernel_domain):
        problems.append("loner: it must stay in the kernel's domain; isolate it another way")
    return problems


class _Visibility:
    """Which of the nodes that should stay hidden the kernel has seen in its graph so far."""

    def __init__(self, rt):
        self.rt = rt
        self.team = self.loner = False

    def everything(self) -> bool:
        """Look at the graph once; True when both the team and the loner have been seen."""
        nodes = self.rt.graph_nodes()
        self.team = self.team or any(as_full_name(_NODES[role]) in nodes for role in ("talker", "listener"))
        self.loner = self.loner or as_full_name(_NODES["loner"]) in nodes
        return self.team and self.loner


def check_domain_plan(plan, rt=None) -> CheckReport:
    """Run the four nodes with the environments ``plan(kernel_domain, spare_domain)`` returns.

    ``plan`` is the student's function; ``rt`` the runtime (the kernel's by default). Returns a
    :class:`CheckReport`. Passes when: the team's listener hears the team's talker; the notebook
    cannot see the team; the notebook sees the monitor; nobody in the kernel's domain sees the loner.
    """
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport("Exercise 07.1 - two teams on one machine")
    kernel_domain = rt.domain.domain_id
    spare_domain = reserve_spare_domain()
    result = report.run("plan() runs", lambda: plan(kernel_domain, spare_domain),
                        hint="plan(kernel_domain, spare_domain) must return a dict.")
    if result is None and not report.criteria:
        report.add("plan() returns a dict", False, "it returned None",
                   hint="End plan() with `return {'talker': {...}, 'listener': {...}, ...}`.")
    if report.criteria:
        return report
    problems = _validate(result, kernel_domain, spare_domain)
    if not report.add("the plan uses only the allowed roles and variables", not problems, "; ".join(problems),
                      hint="Each role maps to a dict such as {'ROS_DOMAIN_ID': str(spare_domain)} or {}."):
        return report
    env = {role: {k: str(v) for k, v in result[role].items()} for role in ROLES}
    try:
        started = time.monotonic()
        children = {role: rt.spawn(_NODES[role], target, params={"name": _NODES[role], **params},
                                   env=env[role]) for role, (target, params) in _TARGETS.items()}
        heard = poll_until(lambda: heard_lines(children["listener"]), 8.0)
        report.add("the team's listener hears the team's talker", bool(heard),
                   "" if heard else "nothing heard in 8 s",
                   hint="Both must share a domain and be able to discover each other (a discovery range "
                        "of OFF hides a node from everyone, its own team included).")
        sees_monitor = poll_until(lambda: "/monitor" in rt.graph_nodes(), 8.0)
        report.add("your notebook sees the monitor", sees_monitor,
                   "" if sees_monitor else "/monitor not in the graph after 8 s",
                   hint="The monitor must be in the kernel's domain with a discovery range that reaches you.")
        # A new process that loses the race for the first answer waits one announcement period
        # (0.1 s with the course's profile, 3 s with Fast DDS's), and a busy machine adds to it: give
        # unwanted visibility a fair chance before declaring the team and the loner hidden.
        seen = _Visibility(rt)
        poll_until(seen.everything, max(0.0, started + UNWANTED_VISIBILITY_WAIT_S - time.monotonic()),
                   period=0.1)
        seen_team, seen_loner = seen.team, seen.loner
        report.add("your notebook cannot see the team", not seen_team,
                   "a team node is in your graph" if seen_team else "",
                   hint="Put the team in another domain: the spare one reserved for you.")
        report.add("nobody in your domain sees the loner", not seen_loner,
                   "/loner is in your graph" if seen_loner else "",
                   hint="Without leaving the domain, a node can switch automatic discovery off: "
                        "ROS_AUTOMATIC_DISCOVERY_RANGE=OFF.")
    finally:
        rt.stop_children(_NODES.values())
    return report


