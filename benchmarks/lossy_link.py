"""Benchmark: best effort and reliable on the QoS lab's lossy link, at several loss levels.

Run with ``.venv/bin/python benchmarks/lossy_link.py [--losses 0 5 10 20 40] [--rate 200] [--seconds 2]``.

Each run is one real ``run_experiment`` on the ``'lossy_link'`` transport (both ends in a private
network namespace whose loopback drops the given share of the datagrams sent to data ports; see
``course_helpers/chapters/ch08b_lab/link.py``), 1 KiB samples, KEEP_LAST deep enough for the whole
run. Printed per loss level and reliability: the delivered share, the loss DDS saw on the way, p50
and p99 latency, and p99 as a ratio to the same reliability's p99 at the lowest loss of this run
(the baseline). ``--json FILE`` also writes the rows.
"""

from __future__ import annotations

import argparse
import json
import sys
import time


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--losses", type=int, nargs="+", default=[0, 5, 10, 20, 40])
    parser.add_argument("--rate", type=float, default=200.0, help="samples per second")
    parser.add_argument("--seconds", type=float, default=2.0, help="how long each run sends")
    parser.add_argument("--json", help="also write the rows to this file")
    args = parser.parse_args(argv)

    from course_helpers import get_runtime
    from course_helpers.chapters.ch08b_lab import ExperimentConfig, link_unavailable_reason, run_experiment

    reason = link_unavailable_reason()
    if reason is not None:
        print(f"skipped: {reason}")
        return 0
    get_runtime()
    count = round(args.rate * args.seconds)
    rows, baseline = [], {}
    print(f"{'loss':>5} {'reliability':<12} {'delivered':>10} {'lost (events)':>14} {'p50 ms':>9} "
          f"{'p99 ms':>9} {'p99 / base':>10} {'run s':>6}")
    for loss in sorted(args.losses):
        for reliability in ("best_effort", "reliable"):
            config = ExperimentConfig(reliability=reliability, depth=min(count, 1000), rate_hz=args.rate,
                                      duration_s=args.seconds, transport="lossy_link", loss_percent=loss)
            started = time.monotonic()
            result = run_experiment(config)
            p99 = result.latency_ms["p99"]
            baseline.setdefault(reliability, p99)
            row = {"loss_percent": loss, "reliability": reliability, "published": result.published,
                   "delivered": result.delivered, "delivered_share": round(result.delivered_ratio, 3),
                   "lost_events": result.lost_events, "in_flight": result.in_flight,
                   "p50_ms": result.latency_ms["p50"], "p99_ms": p99,
                   "p99_ratio": p99 / baseline[reliability] if p99 and baseline[reliability] else None,
                   "run_s": time.monotonic() - started}
            rows.append(row)
            ratio = f"{row['p99_ratio']:.1f}x" if row["p99_ratio"] else "-"
            print(f"{loss:>4}% {reliability:<12} {row['delivered_share']:>10.1%} {result.lost_events:>14} "
                  f"{result.latency_ms['p50'] or 0:>9.1f} {p99 or 0:>9.1f} {ratio:>10} {row['run_s']:>6.1f}",
                  flush=True)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump(rows, handle, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
