"""Leftover Fast DDS shared-memory files, made by real participants killed with SIGKILL.

Which process owns a segment or a port is read from /proc/locks: the owner holds an flock on the
object's ``_el`` file.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys

from course_helpers.core import shm_ports
from course_helpers.core.domains import reserve_domain

# a plain rclpy program with rmw's own LOCALHOST set-up (shared memory on), that waits to be killed
PARTICIPANT = """
import time, rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node('shm_owner')
node.create_subscription(String, 'shm_topic', lambda m: None, 10)
print('ready', flush=True)
time.sleep(120)
"""


def _start(domain: int) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if k != "FASTRTPS_DEFAULT_PROFILES_FILE"}
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    child = subprocess.Popen([sys.executable, "-c", PARTICIPANT], env=env, stdout=subprocess.PIPE, text=True)
    assert child.stdout.readline().strip() == "ready"
    return child


def _kill(child: subprocess.Popen) -> None:
    child.send_signal(signal.SIGKILL)
    child.wait(10)


def _owned_by(pid: int) -> set[str]:
    """The Fast DDS objects in /dev/shm (segments and ports) whose ``_el`` lock ``pid`` holds."""
    with open("/proc/locks", encoding="ascii") as table:
        inodes = {line.split()[5].split(":")[-1] for line in table if line.split()[4] == str(pid)}
    owned = set()
    for name in os.listdir(shm_ports.SHM_DIR):
        if name.startswith("fastrtps_") and name.endswith("_el"):
            try:
                if str(os.stat(os.path.join(shm_ports.SHM_DIR, name)).st_ino) in inodes:
                    owned.add(name[:-3])
            except FileNotFoundError:
                continue
    return owned


def _exists(names: set[str]) -> set[str]:
    return {n for n in names if os.path.exists(os.path.join(shm_ports.SHM_DIR, n))}


def _ports(names: set[str], domain: int | None = None) -> set[str]:
    """The ports among ``names``; with ``domain``, only that domain's (7400 + 250 x domain + ...)."""
    ports = {n for n in names if n.startswith("fastrtps_port")}
    if domain is None:
        return ports
    first = 7400 + 250 * domain
    return {n for n in ports if first <= int(n.removeprefix("fastrtps_port")) < first + 250}


def test_a_reserved_domain_loses_a_killed_participants_ports_and_keeps_a_live_ones():
    stale_domain, live_domain = reserve_domain(), reserve_domain()
    killed, live = _start(stale_domain), _start(live_domain)
    try:
        left = _ports(_owned_by(killed.pid), stale_domain)
        kept = _ports(_owned_by(live.pid), live_domain)
        assert left and kept, "each participant listens on shared-memory ports"
        _kill(killed)
        assert _exists(left) == left, "a killed participant leaves its ports behind"
        assert shm_ports.remove_stale_ports(stale_domain) >= len(left)
        assert not _exists(left)
        assert shm_ports.remove_stale_ports(live_domain) == 0  # a port with a listener stays
        assert _exists(kept) == kept and live.poll() is None
    finally:
        _kill(live)


def test_a_killed_participants_segment_is_removed_and_a_live_ones_kept():
    killed, live = _start(reserve_domain()), _start(reserve_domain())
    try:
        dead = _owned_by(killed.pid) - _ports(_owned_by(killed.pid))
        alive = _owned_by(live.pid) - _ports(_owned_by(live.pid))
        assert dead and alive, "each participant has a segment"
        _kill(killed)
        assert _exists(dead) == dead, "a killed participant leaves its segment behind"
        assert shm_ports.remove_dead_segments() >= len(dead)
        assert not _exists(dead)
        assert _exists(alive) == alive and live.poll() is None
    finally:
        _kill(live)
