"""Benchmark: can ``%ros2 bag record`` keep up with the QoS lab? Its size and write rate, and where it stops.

Run with ``.venv/bin/python benchmarks/bag_record_rate.py [--sizes 1024 65536 1048576] [--rates 100 400]
[--seconds 0.75] [--storage mcap]``.

Each row is one real QoS lab run (``run_experiment``: the lab's publisher in a child process over
shared memory, its subscriber in this process, best effort, KEEP_LAST deep enough for the whole
burst), recorded by the course's recorder (``core/bags``: raw subscription, its own executor, a
writer thread, rosbag2's 100 MiB cache) into a bag in a scratch folder. Printed per row: the lab's
data rate (rate x payload), the samples the publisher sent, what the lab's subscriber delivered,
what the recorder received, wrote and dropped (cache full), the bag's size on disk, the rate the
writer wrote at while the recording lasted, and the recorded share as a ratio to the first row of
the same run (the baseline, the lightest load). A recorder keeps up when it wrote every sample the
publisher sent. ``--json FILE`` also writes the rows.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

MiB = 1024 * 1024


def writer_capacity(folder: Path, storage: str, size: int = MiB, count: int = 200) -> float:
    """MiB/s the bag writer alone stores: ``count`` messages of ``size`` bytes queued at once
    (the baseline of the rows: what the disk and the storage format allow, no ROS involved)."""
    from course_helpers.core.bags import BagWriter

    writer = BagWriter(folder / f"capacity_{storage}", storage, cache_limit_bytes=(count + 1) * size)
    writer.add_topic("/capacity", "std_msgs/msg/UInt8MultiArray", [])
    data = bytes(size)
    started = time.perf_counter()
    for n in range(count):
        writer.write("/capacity", n, data)
    stats = writer.close()
    elapsed = time.perf_counter() - started
    shutil.rmtree(folder / f"capacity_{storage}")
    return stats.bytes_written / MiB / elapsed


def _row(size: int, rate: float, seconds: float, folder: Path, storage: str, reliability: str) -> dict:
    from course_helpers import get_runtime
    from course_helpers.chapters.ch08b_lab import ExperimentConfig, run_experiment
    from course_helpers.core import bags

    rt = get_runtime()
    count = max(1, round(rate * seconds))
    config = ExperimentConfig(reliability=reliability, depth=min(count, 1000), rate_hz=rate,
                              payload_bytes=size, duration_s=seconds)
    path = folder / f"bag_{size}_{rate:g}"
    recording = bags.record(rt, path, regex="^/qos_lab/run_", storage=storage)
    started = time.monotonic()
    result = run_experiment(config)
    stats = recording.stop()  # writes what is still queued, then metadata.yaml
    elapsed = time.monotonic() - started
    on_disk = sum(p.stat().st_size for p in path.iterdir())
    row = {"reliability": reliability, "payload_bytes": size, "rate_hz": rate,
           "offered_MiB_s": round(size * rate / MiB, 3),
           "sent": result.published, "subscriber_delivered": result.delivered,
           "recorder_received": stats.received, "written": stats.written, "dropped_cache_full": stats.dropped,
           "bag_MiB": round(on_disk / MiB, 2), "recording_s": round(elapsed, 2),
           "write_MiB_s": round(stats.bytes_written / MiB / max(stats.write_seconds, 1e-9), 1),
           "recorded_share": round(stats.written / result.published, 3) if result.published else 0.0}
    shutil.rmtree(path)
    return row


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 65536, 262144, 1048576],
                        help="payload bytes per sample")
    parser.add_argument("--rates", type=float, nargs="+", default=[100.0, 400.0], help="samples per second")
    parser.add_argument("--seconds", type=float, default=0.75, help="how long each run sends (the lab: 0.75)")
    parser.add_argument("--storage", choices=["mcap", "sqlite3"], default="mcap")
    parser.add_argument("--reliability", choices=["best_effort", "reliable"], nargs="+",
                        default=["best_effort", "reliable"])
    parser.add_argument("--json", help="also write the rows to this file")
    args = parser.parse_args(argv)

    folder = Path(tempfile.mkdtemp(prefix="bag_record_rate_"))
    rows = []
    capacity = writer_capacity(folder, args.storage)
    print(f"the bag writer alone ({args.storage}, 1 MiB messages): {capacity:.0f} MiB/s (the baseline of "
          f"'/ cap' below)")
    print(f"{'QoS':<11} {'payload':>8} {'rate':>5} {'offered':>12} {'/ cap':>6} {'sent':>5} {'sub got':>7} "
          f"{'rec got':>7} {'written':>7} {'dropped':>7} {'bag':>10} {'writing at':>12} {'share':>6} "
          f"{'/ base':>6}")
    try:
        for reliability in args.reliability:
            for size in sorted(args.sizes):
                for rate in sorted(args.rates):
                    row = _row(size, rate, args.seconds, folder, args.storage, reliability)
                    base = rows[0]["recorded_share"] if rows else row["recorded_share"]
                    row["share_vs_baseline"] = round(row["recorded_share"] / base, 3) if base else 0.0
                    row["offered_vs_capacity"] = round(row["offered_MiB_s"] / capacity, 3)
                    rows.append(row)
                    print(f"{reliability:<11} {size:>8} {rate:>5g} {row['offered_MiB_s']:>6.2f} MiB/s "
                          f"{row['offered_vs_capacity']:>6.2f} {row['sent']:>5} "
                          f"{row['subscriber_delivered']:>7} "
                          f"{row['recorder_received']:>7} {row['written']:>7} {row['dropped_cache_full']:>7} "
                          f"{row['bag_MiB']:>6.2f} MiB {row['write_MiB_s']:>6.0f} MiB/s "
                          f"{row['recorded_share']:>6.3f} {row['share_vs_baseline']:>6.3f}", flush=True)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    for row in rows:
        if row["written"] < row["sent"]:
            dropped = row["dropped_cache_full"]
            where = (f"the recorder itself dropped {dropped} (its cache was full)" if dropped
                     else "the recorder wrote all it received; the rest never reached it (for best effort, "
                          "nor the lab's own subscriber: lost on the way)")
            print(f"{row['reliability']}, {row['payload_bytes']} B at {row['rate_hz']:g} Hz "
                  f"({row['offered_MiB_s']:g} MiB/s): {row['written']} of {row['sent']} recorded; {where}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    from course_helpers import shutdown_runtime

    shutdown_runtime()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
