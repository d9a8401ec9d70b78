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
import json
import statistics
import sys
import time

from course_helpers import get_runtime
from course_helpers.chapters.ch08b_lab.engine import (
    CHILD_LABEL,
    ExperimentConfig,
    make_qos,
    preset,
    run_experiment,
    transport_env,
)


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


def plain_baseline(config: ExperimentConfig) -> tuple[int, float]:
    """Feed a counting-only rclpy subscriber from the lab's publisher; (received, seconds sending)."""
    from course_interfaces.msg import ExperimentSample

    from course_helpers.chapters.ch08b_lab.engine import SUMMARY_TAG

    rt = get_runtime()
    topic = "/qos_lab/plain_baseline"
    received = [0]
    node = rt.node("plain_baseline_subscriber")

    def count(_msg):
        received[0] += 1

    node.create_subscription(ExperimentSample, topic, count, make_qos(config.qos_dict()))
    child = rt.spawn(CHILD_LABEL, "course_helpers.chapters.ch08b_lab.engine:make_lab_publisher",
                     params={"topic": topic, "qos": config.qos_dict(), "rate_hz": config.rate_hz,
                             "payload_bytes": config.payload_bytes, "count": config.count,
                             "deadline_s": config.duration_s * 2 + 2},
                     env=transport_env(config.transport, rt.log_dir))
    try:
        rt.wait_until(lambda: SUMMARY_TAG in child.log(), timeout=config.duration_s * 3 + 20,
                      what="the publisher's summary")
        before = -1
        while received[0] != before:  # let queued samples drain
            before = received[0]
            time.sleep(0.3)
        line = [ln for ln in child.log().splitlines() if ln.startswith(SUMMARY_TAG)][-1]
        seconds = json.loads(line[len(SUMMARY_TAG):])["elapsed_s"]
    finally:
        rt.stop_child(CHILD_LABEL)
        rt.remove(node)
    return received[0], seconds


def throughput_ratio() -> None:
    """Samples per second: the lab's subscriber (alone, and under the live plot) vs a plain one."""
    from course_helpers.chapters.ch08b_lab.panel import qos_lab

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
