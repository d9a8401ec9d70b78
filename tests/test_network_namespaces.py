"""What separates students on one host (docs/classroom.md): domains keep honest kernels apart, a network
namespace keeps everyone apart.

Real processes, each a course runtime with one node, all in the same ROS domain (as a student who sets
``ROS_DOMAIN_ID`` on purpose would put them):

* two plain processes find each other: a domain is no wall against someone who names it;
* a process inside a network namespace of its own (``unshare -n``, loopback up) and one outside do
  not, in either direction, for three times as long as the plain pair needed.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time

import pytest

from course_helpers.core import domains

from .conftest import REPO

PROBE = """
import json, sys
from rclpy.node import Node
from course_helpers import get_runtime

name, other, window = sys.argv[1], sys.argv[2], float(sys.argv[3])
rt = get_runtime()
rt.add(Node, name, console=False)
found = rt.poll_until(lambda: other in rt.graph_nodes(), window)
print(json.dumps({"found": found, "domain": rt.domain.domain_id, "seen": rt.graph_nodes()}), flush=True)
sys.stdin.read()  # stay discoverable until the test has both answers
"""
MIN_WINDOW_S = 5.0  # s; the shortest a namespaced pair is given to find each other
FIND_TIMEOUT_S = 60.0  # s; how long the plain pair may take (a start on a loaded machine is slow)


def _namespace_prefix() -> list[str]:
    """The command prefix that runs a program in a new network namespace with its loopback up."""
    up = ["sh", "-c", 'ip link set lo up && exec "$0" "$@"']
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        pytest.skip("unshare (util-linux) and ip (iproute2) are needed to make a network namespace")
    if os.geteuid() == 0:
        return ["unshare", "--net", "--", *up]
    trial = subprocess.run(["unshare", "--map-root-user", "--net", "true"], capture_output=True, text=True)
    if trial.returncode != 0:
        pytest.skip("making a network namespace needs root or unprivileged user namespaces "
                    f"(sysctl kernel.unprivileged_userns_clone=1): {trial.stderr.strip()}")
    return ["unshare", "--map-root-user", "--net", "--", *up]


def _pair(domain: int, first: list[str], second: list[str], window_s: float) -> tuple[dict, dict]:
    """Run two probes at once in ``domain``, each looking for the other's node for up to ``window_s``."""
    env = {k: v for k, v in os.environ.items() if k not in ("ROS_DOMAIN_ID", "FASTRTPS_DEFAULT_PROFILES_FILE",
                                                          "COURSE_CHANNEL_FD", "COURSE_PARENT_PID")}
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    probes = []
    try:
        for prefix, name, other in ((first, "ns_probe_a", "/ns_probe_b"),
                                    (second, "ns_probe_b", "/ns_probe_a")):
            argv = [*prefix, sys.executable, "-c", PROBE, name, other, str(window_s)]
            probes.append(subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                           stderr=subprocess.PIPE, text=True, cwd=REPO, env=env))
        answers = []
        for probe in probes:
            line = probe.stdout.readline()
            assert line, f"a probe ended without an answer: {probe.stderr.read()[-2000:]}"
            answers.append(json.loads(line))
        return answers[0], answers[1]
    finally:
        for probe in probes:
            probe.stdin.close()
            try:
                probe.wait(20)
            except subprocess.TimeoutExpired:
                probe.kill()
                probe.wait(5)


@pytest.mark.timeout(300)
def test_a_domain_joins_whoever_names_it_and_a_network_namespace_separates():
    inside = _namespace_prefix()
    domain = domains.reserve_domain()  # no other course process uses it meanwhile
    started = time.monotonic()
    a, b = _pair(domain, [], [], FIND_TIMEOUT_S)
    plain_s = time.monotonic() - started
    assert a["found"] and b["found"], (a, b)
    assert a["domain"] == b["domain"] == domain

    window_s = max(MIN_WINDOW_S, 3 * plain_s)
    a, b = _pair(domain, inside, [], window_s)
    assert a["domain"] == b["domain"] == domain
    assert "/ns_probe_a" in a["seen"], f"the namespaced probe's own graph does not work: {a}"
    assert not a["found"] and "/ns_probe_b" not in a["seen"], f"the namespaced probe saw outside: {a}"
    assert not b["found"] and "/ns_probe_a" not in b["seen"], f"the outside probe saw into the namespace: {b}"
