"""Port slots: a child never takes over the ports of a child that was killed just before it.

Real children over real Fast DDS; which ports a child's participants listen on is read from its own
UDP sockets. Why it matters, and the figures, are in ``course_helpers/core/port_slots.py``.
"""

from __future__ import annotations

import socket

import pytest

from course_helpers.core import port_slots
from course_helpers.core.dds_config import SLOT_PROFILE_STEM, slot_lease, slot_profile_env
from tests.helpers_children import hold_a_named_node, report_when_it_sees


def _start(rt, label: str, name: str, participants: int = 1) -> tuple[set[int], str]:
    """Start a child holding ``participants`` participants; its UDP ports and the profile it read."""
    child = rt.spawn(label, hold_a_named_node, {"name": name, "participants": participants})
    ready = child.wait_for_report("ready", 30, f"{label} to make its participants")
    return set(ready["ports"]), ready["profile"]


def _slot_of(profile: str) -> int:
    assert profile.startswith(SLOT_PROFILE_STEM + "_"), profile
    return int(profile.removeprefix(SLOT_PROFILE_STEM + "_").split("_")[0])


def test_a_child_listens_on_the_ports_of_its_slot_and_is_found(rt):
    ports, profile = _start(rt, "slotted", "slotted")
    assert set(port_slots.unicast_ports(rt.domain.domain_id, _slot_of(profile))) <= ports
    rt.wait_until(lambda: "/slotted_0" in rt.graph_nodes(), 20, "the kernel to find the slotted child")


def _unicast(ports: set[int], domain: int) -> set[int]:
    """The ports among ``ports`` that RTPS maps to participants' unicast traffic in ``domain``."""
    return {p for p in ports if 7410 + 250 * domain <= p < 7400 + 250 * (domain + 1)}


def test_a_child_started_after_a_killed_one_never_takes_its_ports(rt):
    """Left to Fast DDS, the second child would take the first one's participant id and ports."""
    domain = rt.domain.domain_id
    first_ports, _ = _start(rt, "first", "first")
    rt.children()["first"].kill()  # SIGKILL, as a crash: no goodbye, its ports stay as they were
    second_ports, _ = _start(rt, "second", "second")
    first, second = _unicast(first_ports, domain), _unicast(second_ports, domain)
    assert first and second and not first & second, (sorted(first), sorted(second))
    rt.wait_until(lambda: "/second_0" in rt.graph_nodes(), 20, "the kernel to find the second child")


def test_a_child_may_make_several_participants_on_its_slot(rt):
    """The slot moves the ports, not the participant ids: a second participant still gets one."""
    _, profile = _start(rt, "pair", "pair", participants=2)
    assert profile.startswith(SLOT_PROFILE_STEM)
    rt.wait_until(lambda: {"/pair_0", "/pair_1"} <= set(rt.graph_nodes()), 20,
                  "the kernel to find both participants' nodes")


def test_children_on_two_slots_find_each_other(rt):
    """Each announces to the 32 ids above its own offset: the lower slot reaches the higher one."""
    _start(rt, "talker_side", "far")
    watcher = rt.spawn("watcher_side", report_when_it_sees, {"name": "far_0"})
    watcher.wait_for_report("seen", 30, "the second child to see the first one's node")


def test_the_slot_given_up_longest_ago_is_taken_first_and_a_held_port_is_skipped(monkeypatch):
    monkeypatch.setattr(port_slots, "_released", {})
    monkeypatch.setattr(port_slots, "_holders", {})
    domain = 77  # only probed: nothing joins it
    ended = lambda: False  # noqa: E731 - a child that has ended
    first = port_slots.take(domain, ended)
    second = port_slots.take(domain, ended)
    assert first != second
    third = port_slots.take(domain, ended)  # the first two ended: a never-used slot comes first
    assert third not in (first, second)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as holder:  # another process's participant
        holder.bind(("127.0.0.1", port_slots.unicast_ports(domain, min(port_slots.SLOTS))[0]))
        monkeypatch.setattr(port_slots, "_released", {})
        monkeypatch.setattr(port_slots, "_holders", {})
        assert port_slots.take(domain, ended) != min(port_slots.SLOTS)


def test_a_running_child_keeps_its_slot(monkeypatch):
    monkeypatch.setattr(port_slots, "_released", {})
    monkeypatch.setattr(port_slots, "_holders", {})
    running = lambda: True  # noqa: E731
    taken = {port_slots.take(78, running) for _ in port_slots.SLOTS}
    assert taken == set(port_slots.SLOTS)
    assert port_slots.take(78, running) is None  # all held: the child gets Fast DDS's own choice


@pytest.mark.parametrize("discovery_range, profile, lease_s", [
    ("LOCALHOST", "/p/course_localhost.xml", 20),
    ("LOCALHOST", f"/p/{SLOT_PROFILE_STEM}_4_domain7.xml", 20),  # a grandchild: not its parent's slot
    ("LOCALHOST", "/p/course_localhost_lease_2000ms.xml", 2.0),  # chapter 01's short lease
    ("LOCALHOST", "/p/course_localhost_lease_2000ms_slot_4_domain7.xml", 2.0),
    ("LOCALHOST", "/p/course_udp_loopback.xml", None),
    ("LOCALHOST", "/p/fastdds_default_discovery.xml", None),
    ("LOCALHOST", "/home/me/mine.xml", None),  # the user's own profile
    ("SUBNET", "/p/course_timing.xml", None),
])
def test_children_on_the_course_localhost_profile_get_a_slot_and_keep_their_lease(discovery_range, profile,
                                                                                    lease_s):
    env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": discovery_range, "FASTRTPS_DEFAULT_PROFILES_FILE": profile}
    assert slot_lease(env) == lease_s


def test_the_slot_profile_moves_both_unicast_offsets(tmp_path):
    path = slot_profile_env(str(tmp_path), 5, 3)["FASTRTPS_DEFAULT_PROFILES_FILE"]
    text = open(path, encoding="utf-8").read()
    assert "<offsetd1>20</offsetd1>" in text and "<offsetd3>21</offsetd3>" in text
    assert "<participantID>" not in text  # a second participant in the process must still get an id
    assert "<port>8160</port>" in text and "<port>8222</port>" in text  # ids 0 and 31 of domain 3: peers
    short = slot_profile_env(str(tmp_path), 5, 3, 2.0)["FASTRTPS_DEFAULT_PROFILES_FILE"]
    assert short.endswith("course_localhost_lease_2000ms_slot_5_domain3.xml")
    assert "<leaseDuration><sec>2</sec>" in open(short, encoding="utf-8").read()
