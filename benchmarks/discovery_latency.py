"""Benchmark: how fast a node in a new process is discovered, course settings against the defaults.

Run with ``make bench`` or ``.venv/bin/python benchmarks/discovery_latency.py [--runs 20]``.

Four set-ups are measured in the same run, one after another, each in a ROS domain of its own
with localhost-only discovery:

* ``course``: the course as a notebook runs it. The anchor is a node of this process's runtime, as
  the kernel's nodes are, and fresh probe processes are its children (``rt.spawn``), with the course's
  Fast DDS profile (``course_helpers/core/dds_config.py``: announcements every 0.1 s, the graph
  reader's first request after 2 ms, a 300 ms shared-memory health check, the kernel told last);
* ``course-children``: the same profile, with the anchor in a child process too (two children that
  meet, such as a talker and a listener started from a notebook);
* ``fastdds-default``: as ``course-children``, with Fast DDS's default discovery settings (3 s,
  70 ms, 1000 ms) and rmw_fastrtps's own LOCALHOST transports;
* ``plain-rclpy``: an anchor and probes written in plain rclpy (no course code at all), with
  Fast DDS's defaults: the baseline a student gets from a textbook script.

For every probe, times are counted from the moment it *calls* for its node (``rt.add`` or ``Node()``,
the call that creates the process's participant and so starts its discovery), which is what a user
waits for, until

* ``anchor sees new``: the anchor process lists the new node in its graph;
* ``new sees anchor``: the new process lists the anchor's node;
* ``sub matched``: the new node's subscription matches the anchor's publisher.

**The floor.** A trace of the loopback traffic (decoded by tshark) shows where the time goes once the
participant exists, a few ms after the call:

1. the new participant announces itself to the discovery ports of participant ids 0 to 31 (a course
   child from 31 down to 0) before it listens (Fast DDS 2.14's ``RTPSParticipantImpl::enable()``
   sends first and registers its receivers after), and each participant already running answers at
   once, with its own announcement and a heartbeat of each endpoint-discovery writer;
2. each side's endpoint-discovery readers ask the other's writers for their history, 10 ms after that
   heartbeat, and Fast DDS answers after a fixed 100 ms (``edp_nack_response_delay`` in
   ``EDPSimple.cpp``; 100 ms in Fast DDS 2.14.5, as the trace shows, since eProsima/Fast-DDS#5540
   corrected a value that had read 100 us): only then does the newcomer know the anchor's graph
   reader;
3. the graph readers' requests (after ``GRAPH_ACKNACK_S``) bring each side the other's node list.

That is about 0.13 s from the call. The kernel holds participant id 0, so a child tells it last and
hears its answer: ``GOAL_S`` is that path with room for creating the participant. Between two children
the answer can come back while the newcomer is still sending to the ports after the anchor's, and it
is dropped, heartbeats and all. The newcomer then learns of the anchor at the anchor's next periodic
announcement (0 to ``ANNOUNCEMENT_S``), and its readers ask only after their first-request delay
(``EDP_FIRST_REQUEST_S``, a default no profile reaches), before the 100 ms answer: 0.21 to 0.30 s in
all, which ``CHILDREN_GOAL_S`` allows.

Earlier versions of this script counted from the moment the constructor *returned*, and sightings
before it were counted as 0: whatever part of the 100 ms fell inside the constructor was hidden, and
how much did depended on how long the constructor took to load its modules. Earlier versions also
timed only two children, as ``course-children`` does.

How long the call itself takes is reported too (``create node``); discovery runs beside it, in Fast DDS's
threads.

The set-ups run one after another, and each one's anchor stops before the next set-up starts.
Every participant's graph reader listens on a shared-memory port from one range for the whole
machine (7000-7399, whatever the domain), and a port stays while any process still holds it, with
the health-check timeout of the process that created it. Interleaved, with the default set-ups'
anchors alive, a course probe sometimes took over a port that a default-configured probe had just
left, and the course anchor's first write to it could wait 333 ms: the cost of sharing a machine with running
programs that use Fast DDS's defaults, not of the course's settings (measured: course p90 0.39 s
in one interleaved run of three, 0.14-0.20 s in one-after-another runs, in either order).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import threading
import time

from benchmarks.discovery_targets import PROBE_TIMEOUT_S, Beacon, BeaconAnchor, probe_procedure
from course_helpers.core import processes
from course_helpers.core.dds_config import ANNOUNCEMENT_S, PROFILE_ENV, default_discovery_env
from course_helpers.core.domains import reserve_domain
from course_helpers.core.runtime import get_runtime
from course_helpers.core.waiting import poll_until

KEYS = ("anchor sees new", "new sees anchor", "sub matched")
EDP_ANSWER_S = 0.1  # s; Fast DDS 2.14's fixed delay before endpoint discovery answers a request
EDP_FIRST_REQUEST_S = 0.07  # s; Fast DDS's default first request of an endpoint reader (not settable)
GOAL_S = round(EDP_ANSWER_S + 0.1, 3)  # s; course p90 from the call: the kernel's answer is heard
CHILDREN_GOAL_S = round(ANNOUNCEMENT_S + EDP_FIRST_REQUEST_S + EDP_ANSWER_S + 0.1, 3)  # s; one may be lost


# ---------------------------------------------------------------------- plain rclpy processes
PLAIN_ANCHOR = """
import json, signal, sys, time
import rclpy
from rclpy.node import Node
from std_msgs.msg import String
rclpy.init()
signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))  # the benchmark's stop: leave quietly
node = Node('bench_anchor')
publisher = node.create_publisher(String, 'bench_beacon', 10)
seen = set()
def look():
    now = time.monotonic()
    for name, namespace in node.get_node_names_and_namespaces():
        full = namespace.rstrip('/') + '/' + name
        if full not in seen:
            seen.add(full)
            print(json.dumps({'node': full, 't': now}), flush=True)
timer = node.create_timer(0.002, look)
try:
    rclpy.spin(node)
except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
    pass
"""

PLAIN_PROBE = """
import json, signal, sys, time
import rclpy
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from std_msgs.msg import String
rclpy.init()
signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))  # the benchmark's stop: leave quietly
start = time.monotonic()
matched = []
node = Node('bench_probe_' + sys.argv[1])
events = SubscriptionEventCallbacks(matched=lambda s: matched.append(time.monotonic()))
node.create_subscription(String, 'bench_beacon', lambda m: None, 10, event_callbacks=events)
created = time.monotonic()
seen = None
while time.monotonic() - created < float(sys.argv[2]) and (seen is None or not matched):
    rclpy.spin_once(node, timeout_sec=0.002)
    names = [ns.rstrip('/') + '/' + n for n, ns in node.get_node_names_and_namespaces()]
    if seen is None and '/bench_anchor' in names:
        seen = time.monotonic()
result = {'start': start, 'created': created, 'seen': seen, 'matched': matched[0] if matched else None}
print(json.dumps(result), flush=True)
# stay discoverable until the benchmark ends this process (once the anchor has listed it)
while time.monotonic() - created < float(sys.argv[2]):
    rclpy.spin_once(node, timeout_sec=0.05)
"""


def _plain_env(domain: int) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in (PROFILE_ENV, "COURSE_CHANNEL_FD")}
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    return env


# ---------------------------------------------------------------------- the set-ups
class KernelSetup:
    """The course as a notebook runs it: the anchor is a node of this process's runtime (the kernel's
    participant, the first of its domain), the probes are children started with ``rt.spawn``."""

    label = "course"

    def __init__(self):
        self.anchor = get_runtime().add(Beacon)

    def probe(self, index: int) -> dict:
        rt = get_runtime()
        name = f"/bench_probe_{index}"
        child = rt.spawn("course_probe", probe_procedure, params={"index": index})
        saw = None

        def kernel_saw() -> bool:
            nonlocal saw
            if saw is None and name in rt.graph_nodes():
                saw = time.monotonic()
            return saw is not None

        try:  # woken by each change of the graph; the probe stays until it is seen (PROBE_TIMEOUT_S)
            rt.poll_until(lambda: kernel_saw() or not child.alive, PROBE_TIMEOUT_S + 30)
            result = child.wait_for_report("result", PROBE_TIMEOUT_S + 30)
        finally:
            rt.stop_child(child.label)
        return {**result, "anchor_saw": saw}

    def stop(self) -> None:
        get_runtime().remove(self.anchor)


class CourseSetup:
    """An anchor child and probe children through the course's process layer."""

    def __init__(self, label: str, env: dict):
        self.label, self.env = label, env
        self.key = label.replace("-", "_")  # process labels are node-name-like
        self.anchor = get_runtime().spawn(f"{self.key}_anchor", BeaconAnchor, env=self.env)
        self.anchor.wait_for_report("ready", 30)

    def probe(self, index: int) -> dict:
        rt = get_runtime()
        child = rt.spawn(f"{self.key}_probe", probe_procedure, params={"index": index}, env=self.env)
        result = child.wait_for_report("result", PROBE_TIMEOUT_S + 30)
        name = f"/bench_probe_{index}"

        def anchor_saw():
            return [r["t"] for r in self.anchor.reports("seen") if r["node"] == name]

        # the probe stays until the anchor lists it (or PROBE_TIMEOUT_S from its creation)
        rt.poll_until(anchor_saw, max(0.0, result["created"] + PROBE_TIMEOUT_S - time.monotonic()))
        rt.stop_child(child.label)
        seen = anchor_saw()
        return {**result, "anchor_saw": seen[0] if seen else None}

    def stop(self) -> None:
        get_runtime().stop_child(self.anchor.label)


class PlainSetup:
    """An anchor and probes in plain rclpy, started as ordinary programs."""

    label = "plain-rclpy"

    def __init__(self, domain: int):
        self.env = _plain_env(domain)
        self.anchor = subprocess.Popen([sys.executable, "-c", PLAIN_ANCHOR], env=self.env,
                                       stdout=subprocess.PIPE, text=True)
        self.seen: dict[str, float] = {}
        threading.Thread(target=self._read_anchor, name="plain-anchor-reader", daemon=True).start()

    def _read_anchor(self) -> None:
        """The anchor prints each node as it sees it, with its own clock's time."""
        for line in self.anchor.stdout:
            entry = json.loads(line)
            self.seen.setdefault(entry["node"], entry["t"])

    def probe(self, index: int) -> dict:
        probe = subprocess.Popen([sys.executable, "-c", PLAIN_PROBE, str(index), str(PROBE_TIMEOUT_S)],
                                 env=self.env, stdout=subprocess.PIPE, text=True)
        try:
            result = json.loads(probe.stdout.readline())
            name = f"/bench_probe_{index}"
            # the probe stays until the anchor lists it (or PROBE_TIMEOUT_S from its creation)
            remaining = result["created"] + PROBE_TIMEOUT_S - time.monotonic()
            poll_until(lambda: name in self.seen, max(0.0, remaining))
        finally:
            probe.terminate()
            probe.wait(timeout=10)
        return {**result, "anchor_saw": self.seen.get(name)}

    def stop(self) -> None:
        self.anchor.terminate()
        self.anchor.wait(timeout=10)


# ---------------------------------------------------------------------- measuring
def latencies(result: dict) -> dict:
    """A probe's times, in seconds from its call for the node (``result["start"]``)."""
    start = result["start"]

    def since(t):
        return None if t is None else t - start

    return {"create node": result["created"] - result["start"],
            "anchor sees new": since(result["anchor_saw"]),
            "new sees anchor": since(result["seen"]), "sub matched": since(result["matched"])}


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))]


def slowest(row: dict) -> float:
    """A probe's longest of the three times (one that never happened counts as ``PROBE_TIMEOUT_S``)."""
    return max(PROBE_TIMEOUT_S if row[key] is None else row[key] for key in KEYS)


def summarize(rows: list[dict], key: str, timeout: float) -> tuple[float, float, int]:
    """(p50, p90, misses); a probe that never saw it counts as the timeout."""
    values = [row[key] if row[key] is not None else timeout for row in rows]
    misses = sum(row[key] is None for row in rows)
    return statistics.median(values), percentile(values, 0.9), misses


def measure(start_setup, runs: int) -> tuple[str, list[dict]]:
    """Start a set-up (``start_setup()`` returns it), time ``runs`` fresh probe processes against its
    anchor, stop it; (its label, each probe's :func:`latencies`)."""
    setup = start_setup()
    rows = []
    time.sleep(1.0)  # the anchor is up and announced
    try:
        for index in range(runs):
            rows.append(latencies(setup.probe(index)))
    finally:
        setup.stop()
    return setup.label, rows


def worst_p90(rows: list[dict]) -> float:
    """A set-up's worst p90 of the three times (a probe that missed counts as ``PROBE_TIMEOUT_S``)."""
    return max(summarize(rows, key, PROBE_TIMEOUT_S)[1] for key in KEYS)


def course_p90(runs: int) -> float:
    """The headline figure: the course set-up's (the kernel and its children) worst p90 of the three,
    over ``runs`` fresh processes."""
    return worst_p90(measure(KernelSetup, runs)[1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=20, help="fresh processes per set-up (default 20)")
    args = parser.parse_args(argv)
    if not 1 <= args.runs <= 200:
        parser.error(f"--runs must be 1..200, got {args.runs}")
    rt = get_runtime()
    course_domain, default_domain, plain_domain = (reserve_domain() for _ in range(3))
    phases = [  # one after another (see the module's docstring)
        KernelSetup,
        lambda: CourseSetup("course-children", {"ROS_DOMAIN_ID": course_domain}),
        lambda: CourseSetup("fastdds-default",
                            {"ROS_DOMAIN_ID": default_domain, **default_discovery_env(rt.log_dir)}),
        lambda: PlainSetup(plain_domain),
    ]
    rows: dict[str, list[dict]] = {}
    for start in phases:
        label, rows[label] = measure(start, args.runs)
        print(f"  {label}: {args.runs} fresh processes done", flush=True)
    print(f"\nDiscovery of a node in a new process, {args.runs} fresh processes per set-up "
          "(seconds from the call that creates the node; p50 / p90):")
    print(f"{'set-up':<17}{'create node':>16}" + "".join(f"  {k:>24}" for k in KEYS))
    for label, data in rows.items():
        cells = [f"{statistics.median(r['create node'] for r in data):.3f} / "
                 f"{percentile([r['create node'] for r in data], 0.9):.3f}"]
        for key in KEYS:
            p50, p90, misses = summarize(data, key, PROBE_TIMEOUT_S)
            cells.append(f"{p50:.3f} / {p90:.3f}" + (f" ({misses} missed)" if misses else ""))
        print(f"{label:<17}{cells[0]:>16}" + "".join(f"  {c:>24}" for c in cells[1:]))  # never run together
    worst = {label: worst_p90(data) for label, data in rows.items()}
    course, children, plain = worst["course"], worst["course-children"], worst["plain-rclpy"]
    late = sum(1 for row in rows["course"] if slowest(row) > GOAL_S)
    print(f"\ncourse p90 (the kernel and a child, worst of the three): {course:.3f} s (goal <= {GOAL_S} s "
          f"from the call: {'met' if course <= GOAL_S else 'NOT met'}); plain rclpy p90: {plain:.3f} s; "
          f"ratio course / plain: {course / plain:.2f}")
    print(f"  {late} of {args.runs} children took longer than {GOAL_S} s: the kernel's first answer came "
          "before the child listened (see the floor)")
    print(f"two children p90: {children:.3f} s (goal <= {CHILDREN_GOAL_S} s: "
          f"{'met' if children <= CHILDREN_GOAL_S else 'NOT met'}); "
          f"ratio to plain rclpy: {children / plain:.2f}")
    processes.stop_all()
    return 0


if __name__ == "__main__":
    sys.exit(main())
