"""What a QoS lab run measured: :class:`Snapshot` (where a run stands) and :class:`ExperimentResult`.

Also the two measurements that need no ROS: :func:`latency_percentiles` of the
subscriber's latencies and :func:`loopback_bytes`, the traffic through this machine's
loopback interface.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from course_helpers.chapters.ch08b_lab.config import ExperimentConfig
from course_helpers.core.machine_load import MachineLoad
from course_helpers.core.units import format_bytes


@dataclass(frozen=True)
class Snapshot:
    """Where a run stands: sent by ``progress`` callbacks and kept in ``ExperimentResult.timeline``."""

    t: float  # seconds since the publisher started sending
    delivered: int  # samples the subscriber's callback got
    lost_by_sequence: int  # gaps in publication_sequence_number (plus the tail, at the end)
    lost_events: int  # DDS message_lost event count
    published: int  # samples the publisher's publish() accepted
    publish_errors: int  # publish() calls that raised
    in_flight: int = 0  # at the end of a run cut short: sent, not yet seen (not counted as lost)
    latency_p50_ms: float | None = None
    latency_p90_ms: float | None = None
    latency_p99_ms: float | None = None
    done: bool = False


@dataclass
class ExperimentResult:
    """What one run measured. ``as_row()`` gives the lab's results-table row."""

    config: ExperimentConfig
    planned: int
    published: int
    publish_errors: int
    not_attempted: int
    delivered: int
    lost_by_sequence: int
    lost_events: int
    in_flight: int  # sent, not yet seen when the run was stopped or cut short (not counted as lost)
    latency_ms: dict  # 'p50', 'p90', 'p99', 'max' (None when nothing arrived)
    send_time_s: float  # how long the publisher took to send everything
    wall_time_s: float  # the whole run, child start to clean-up
    loopback_bytes: int  # bytes through this machine's 'lo' interface during the run
    stopped: bool  # ended early by stop_event
    first_error: str = ""
    first_seq: int | None = None  # late joiner: the oldest sample's sequence number it got
    timeline: list[Snapshot] = field(default_factory=list, repr=False)
    end_reason: str = ""  # with samples in flight: why the run ended before they arrived
    machine: MachineLoad | None = None  # what else used the machine during the run
    writer_gid: str = ""  # the publisher's DDS writer GUID (32 hex digits), as it reported it

    @property
    def finished(self) -> bool:
        """True when the run was neither stopped nor ended with samples still in flight."""
        return not self.stopped and not self.in_flight

    @property
    def label(self) -> str:
        """The run's name in tables and plots (``config.describe()``)."""
        return self.config.describe()

    @property
    def delivered_ratio(self) -> float:
        """Delivered / published (0 when nothing was published)."""
        return self.delivered / self.published if self.published else 0.0

    @property
    def lost_nothing(self) -> bool:
        """True when neither way of counting saw a loss."""
        return self.lost_by_sequence == 0 and self.lost_events == 0

    def as_row(self) -> dict:
        """One row of the results table (plain values)."""
        c = self.config
        lat = self.latency_ms
        return {
            "run": c.describe(),
            "reliability": c.reliability, "durability": c.durability,
            "history": "keep_all" if c.history == "keep_all" else f"keep_last {c.depth}",
            "rate_hz": c.rate_hz, "payload": format_bytes(c.payload_bytes),
            "processing_ms": c.processing_ms, "transport": c.transport,
            "published": self.published, "delivered": self.delivered,
            "lost_seq": self.lost_by_sequence, "lost_events": self.lost_events,
            "in_flight": self.in_flight, "publish_errors": self.publish_errors,
            "p50_ms": _round(lat.get("p50")), "p99_ms": _round(lat.get("p99")),
            "loopback_mb": round(self.loopback_bytes / 1e6, 1), "stopped": self.stopped,
            "finished": self.finished, "busy": bool(self.machine and self.machine.busy),
        }

    def summary(self) -> str:
        """One line in words."""
        if self.config.late_joiner:
            return (f"{self.label}: the late joiner got {self.delivered} of the {self.published} "
                    "samples sent before it joined")
        text = f"{self.label}: "
        if self.in_flight:  # the headline: these numbers are not the run's outcome
            text += (f"NOT FINISHED, {self.in_flight} of {self.published} samples still in flight, not lost "
                     f"({self.end_reason or 'the run ended before they arrived'}); so far ")
        text += f"delivered {self.delivered} of {self.published} sent"
        if self.lost_nothing and not self.in_flight and self.delivered == self.published:
            text += ", nothing lost"
        else:
            text += (f", lost {self.lost_by_sequence} by sequence gaps and {self.lost_events} by "
                     "message_lost events")
        if self.publish_errors:
            text += f", {self.publish_errors} publish() errors"
        return text + (" (stopped)" if self.stopped and not self.in_flight else "")

    def to_dict(self) -> dict:
        """Every field as plain values (the config as a dict, the timeline as a list of dicts)."""
        out = asdict(self)
        out["config"] = asdict(self.config)
        return out


def _round(value):
    return None if value is None else round(value, 2)


def latency_percentiles(latency_ns) -> dict:
    """p50/p90/p99/max latency in ms from an array of nanoseconds (None values when empty)."""
    if not len(latency_ns):
        return {"p50": None, "p90": None, "p99": None, "max": None}
    import numpy as np

    # Copy first (a slice is one atomic C copy): a buffer view of the live array would make the
    # subscriber's append() in the executor thread fail while the view exists.
    values = np.frombuffer(latency_ns[:], dtype=np.int64) / 1e6
    p50, p90, p99 = np.percentile(values, [50, 90, 99])
    return {"p50": float(p50), "p90": float(p90), "p99": float(p99), "max": float(values.max())}


def loopback_bytes(pid: int | str = "self") -> int:
    """Bytes received so far on a loopback interface: this machine's, or (``pid``) that of the network
    namespace process ``pid`` lives in (from /proc/PID/net/dev; 0 if unknown)."""
    try:
        with open(f"/proc/{pid}/net/dev", encoding="ascii") as handle:
            for line in handle:
                name, _, data = line.partition(":")
                if name.strip() == "lo":
                    return int(data.split()[0])
    except (OSError, ValueError, IndexError):
        pass
    return 0
