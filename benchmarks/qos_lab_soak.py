"""Soak test of the QoS lab (chapter 08): does "best-effort vs reliable under load" hold up?

Runs the preset "best-effort vs reliable under load" N times (default 20) over the
real transport and counts the runs in which the reliable subscriber got at least
as many samples as the best-effort one. It is a count, not a timed test: the
machine is shared, so single runs vary.

Then it compares the lab's subscriber (the kernel-side node that counts sequence
gaps, message_lost events and latency) with a plain rclpy subscriber whose
callback only counts, both fed by the same child-process publisher at the lab's
highest rate, and prints the ratio of samples per second.

Usage: python benchmarks/qos_lab_soak.py [--runs 20]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

from course_interfaces.msg import ExperimentSample
from rclpy.node import Node

from course_helpers import get_runtime
from course_helpers.chapters.ch08b_lab import (
    CHILD_LABEL,
    ExperimentConfig,
    LabPublisher,
    preset,
    qos_lab,
    run_experiment,
)
from course_helpers.core.dds_config import udp_loopback_env
from course_helpers.core.qos_dict import qos_from_dict
from course_helpers.core.waiting import wait_until

QUIET_S = 0.3  # the queued samples have drained when nothing arrived for this long


def soak(runs: int) -> int:
    best_effort_cfg, reliable_cfg = preset("best-effort vs reliable under load")
    wins = 0
    be_counts, rel_counts = [], []
    for number in range(1, runs + 1):
        best_effort = run_experiment(best_effort_cfg)
        reliable = run_experiment(reliable_cfg)
        ok = reliable.delivered >= best_effort.delivered
        wins += ok
        be_counts.append(best_effort.delivered)
        rel_counts.append(reliable.delivered)
        print(f"run {number:2d}: best-effort {best_effort.delivered:3d}/{best_effort.published} "
              f"(lost {best_effort.lost_by_sequence} by gaps, {best_effort.lost_events} by events), "
              f"reliable {reliable.delivered:3d}/{reliable.published} "
              f"(lost {reliable.lost_by_sequence} by gaps, {reliable.lost_events} by events)"
              f"{'' if ok else '  <-- reliable < best-effort'}", flush=True)
    print(f"{wins}/{runs} runs: reliable >= best-effort")
    print(f"delivered of {best_effort_cfg.count}: best-effort median {statistics.median(be_counts):.0f} "
          f"(range {min(be_counts)}-{max(be_counts)}), reliable median {statistics.median(rel_counts):.0f} "
          f"(range {min(rel_counts)}-{max(rel_counts)})")
    return wins


class CountingSubscriber(Node):
    """A plain rclpy subscriber whose callback only counts (and notes when the last sample came)."""

    def __init__(self, topic: str, qos: dict):
        super().__init__("plain_baseline_subscriber")
        self.received = 0
        self.last_arrival = time.monotonic()
        self.subscription = self.create_subscription(ExperimentSample, topic, self.on_sample,
                                                     qos_from_dict(qos))

    def on_sample(self, _msg) -> None:
        self.received += 1
        self.last_arrival = time.monotonic()


def plain_baseline(config: ExperimentConfig) -> tuple[int, float]:
    """Feed a counting-only rclpy subscriber from the lab's publisher; (received, seconds sending)."""
    rt = get_runtime()
    topic = "/qos_lab/plain_baseline"
    node = rt.add(CountingSubscriber, topic, config.qos_dict(), console=False)
    child = rt.spawn(CHILD_LABEL, LabPublisher,
                     params={"topic": topic, "qos": config.qos_dict(), "rate_hz": config.rate_hz,
                             "payload_bytes": config.payload_bytes, "count": config.count,
                             "deadline_s": config.duration_s * 2 + 2},
                     env=udp_loopback_env(rt.log_dir) if config.transport == "udp" else {})
    try:
        summary = child.wait_for_report("summary", config.duration_s * 3 + 20, "the publisher's summary")
        wait_until(lambda: time.monotonic() - node.last_arrival >= QUIET_S, 30.0,
                   "the queued samples to drain")
    finally:
        rt.stop_child(CHILD_LABEL)
        rt.remove(node)
    return node.received, summary["elapsed_s"]


def throughput_ratio() -> None:
    """Samples per second: the lab's subscriber (alone, and under the live plot) vs a plain one."""
    config = ExperimentConfig(reliability="best_effort", depth=1000, rate_hz=5000, payload_bytes=16,
                              duration_s=2.0, label="throughput")
    lab = run_experiment(config)
    lab_rate = lab.delivered / max(lab.send_time_s, 1e-3)
    panel = qos_lab()
    try:
        panel.start([config])
        panel.wait(60)
        (live,) = panel.results
        live_rate = live.delivered / max(live.send_time_s, 1e-3)
        frame_hz = panel.frame_hz or 0.0
    finally:
        panel.close()
    plain, seconds = plain_baseline(config)
    plain_rate = plain / max(seconds, 1e-3)
    print(f"subscriber throughput, {config.count} samples of {config.payload_bytes} B at "
          f"{config.rate_hz:g} Hz, best effort, depth {config.depth}:")
    print(f"  plain rclpy subscriber (callback only counts): {plain}/{config.count} = {plain_rate:.0f}/s")
    print(f"  lab subscriber (gaps, events, latency):        {lab.delivered}/{config.count} = "
          f"{lab_rate:.0f}/s, ratio lab/plain = {lab_rate / plain_rate:.2f}")
    print(f"  lab subscriber + live plot in the panel:       {live.delivered}/{config.count} = "
          f"{live_rate:.0f}/s, ratio = {live_rate / plain_rate:.2f}; the plot refreshed at {frame_hz:.1f} Hz")


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--no-baseline", action="store_true", help="skip the throughput comparison")
    args = parser.parse_args(argv)
    rt = get_runtime()
    try:
        wins = soak(args.runs)
        if not args.no_baseline:
            throughput_ratio()
        if rt.errors:
            print("callback errors:", *rt.errors, sep="\n  ")
    finally:
        rt.stop()
    return 0 if wins == args.runs else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
