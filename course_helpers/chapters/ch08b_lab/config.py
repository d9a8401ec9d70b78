"""What one QoS lab run measures: :class:`ExperimentConfig`, its limits, and the lab's presets.

``ExperimentConfig(reliability='best_effort', depth=5, rate_hz=400, payload_bytes=2**20)``
checks every field when it is made and raises :class:`CourseError` naming what is not
allowed; ``PRESETS`` and :func:`preset` hold the lab's one-click scenarios.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from course_helpers.core.errors import CourseError
from course_helpers.core.units import format_bytes, format_rate

RELIABILITY = ("reliable", "best_effort")
DURABILITY = ("volatile", "transient_local")
HISTORY = ("keep_last", "keep_all")
TRANSPORTS = {
    "shm": "shared memory (what Fast DDS uses between processes on one machine)",
    "udp": "UDP through the loopback interface only (as between two machines)",
    "lossy_link": "UDP over a private network link that drops loss_percent of the data datagrams "
                  "(both ends in child processes inside a network namespace)",
}
MAX_LOSS_PERCENT = 50
MAX_LINK_MBIT = 10_000.0
MIN_LINK_MBIT = 5.0  # the lab's discovery alone (announcements to 32 ports, 10 a second) needs ~3 Mbit/s
MAX_RATE_HZ = 5000.0
MAX_PAYLOAD_BYTES = 4 * 1024 * 1024  # 4 MiB
MIN_DURATION_S, MAX_DURATION_S = 0.1, 20.0
MAX_SAMPLES = 40_000  # rate x duration
MAX_DEPTH = 1000
MAX_PROCESSING_MS = 200.0
MAX_KEEP_ALL_BYTES = 512 * 1024 * 1024  # a KEEP_ALL writer may hold every sample in memory


@dataclass(frozen=True)
class ExperimentConfig:
    """One lab configuration: QoS of both ends, the load, and the transport.

    reliability: 'reliable' | 'best_effort'; durability: 'volatile' | 'transient_local';
    history: 'keep_last' (uses ``depth``) | 'keep_all' (``depth`` must be None: KEEP_ALL
    keeps every sample until it is acknowledged, so a depth would mean nothing).
    rate_hz: samples per second the publisher sends; payload_bytes: size of each
    sample's filler; processing_ms: how long the subscriber's callback works on each
    sample; transport: 'shm' (Fast DDS default, shared memory) | 'udp' (UDP loopback only);
    duration_s: how long the publisher sends (it sends ``rate_hz * duration_s`` samples);
    late_joiner: the subscriber is created only after the publisher has sent everything;
    label: a name for tables and plots (default: :meth:`describe` builds one);
    loss_percent: with transport 'lossy_link', the share of data datagrams the link drops (0..50);
    link_mbit: with transport 'lossy_link', the link's capacity in Mbit/s (0: no limit).
    """

    reliability: str = "reliable"
    durability: str = "volatile"
    history: str = "keep_last"
    depth: int | None = 10
    rate_hz: float = 100.0
    payload_bytes: int = 1024
    processing_ms: float = 0.0
    transport: str = "shm"
    duration_s: float = 2.0
    late_joiner: bool = False
    label: str = ""
    loss_percent: int = 0
    link_mbit: float = 0.0

    def __post_init__(self):
        _check_choice("reliability", self.reliability, RELIABILITY)
        _check_choice("durability", self.durability, DURABILITY)
        _check_choice("history", self.history, HISTORY)
        _check_choice("transport", self.transport, tuple(TRANSPORTS))
        if self.history == "keep_all":
            if self.depth is not None:
                raise CourseError(
                    f"depth={self.depth!r} with history='keep_all': KEEP_ALL keeps every sample "
                    "until every reader has it, so a depth means nothing. Pass depth=None with "
                    "'keep_all', or use history='keep_last' with a depth of 1.."
                    f"{MAX_DEPTH}.")
        elif (isinstance(self.depth, bool) or not isinstance(self.depth, int)
              or not 1 <= self.depth <= MAX_DEPTH):
            raise CourseError(f"depth must be a whole number from 1 to {MAX_DEPTH} with "
                              f"history='keep_last', got {self.depth!r}")
        _check_number("rate_hz", self.rate_hz, 1.0, MAX_RATE_HZ, "samples per second")
        if (isinstance(self.payload_bytes, bool) or not isinstance(self.payload_bytes, int)
                or not 0 <= self.payload_bytes <= MAX_PAYLOAD_BYTES):
            raise CourseError(f"payload_bytes must be a whole number from 0 to {MAX_PAYLOAD_BYTES} "
                              f"(4 MiB), got {self.payload_bytes!r}")
        _check_number("processing_ms", self.processing_ms, 0.0, MAX_PROCESSING_MS,
                      "milliseconds per sample")
        _check_number("duration_s", self.duration_s, MIN_DURATION_S, MAX_DURATION_S, "seconds")
        if self.count > MAX_SAMPLES:
            raise CourseError(
                f"rate_hz x duration_s = {self.count} samples; the lab allows at most {MAX_SAMPLES} "
                "per run. Lower the rate or the duration.")
        if self.history == "keep_all" and self.count * self.payload_bytes > MAX_KEEP_ALL_BYTES:
            raise CourseError(
                f"KEEP_ALL may hold every unacknowledged sample in memory: {self.count} samples x "
                f"{self.payload_bytes} bytes is more than {MAX_KEEP_ALL_BYTES // 2**20} MiB. "
                "Lower the rate, the duration or the payload, or use 'keep_last'.")
        if not isinstance(self.late_joiner, bool):
            raise CourseError(f"late_joiner must be True or False, got {self.late_joiner!r}")
        if not isinstance(self.label, str):
            raise CourseError(f"label must be a string, got {self.label!r}")
        self._check_link()

    def _check_link(self) -> None:
        if (isinstance(self.loss_percent, bool) or not isinstance(self.loss_percent, int)
                or not 0 <= self.loss_percent <= MAX_LOSS_PERCENT):
            raise CourseError(f"loss_percent must be a whole number from 0 to {MAX_LOSS_PERCENT}, "
                              f"got {self.loss_percent!r}")
        _check_number("link_mbit", self.link_mbit, 0.0, MAX_LINK_MBIT, "Mbit/s (0: no limit)")
        if 0 < self.link_mbit < MIN_LINK_MBIT:
            raise CourseError(f"link_mbit must be 0 (no limit) or at least {MIN_LINK_MBIT:g} Mbit/s: below "
                              "that the lab's own discovery traffic (about 3 Mbit/s) fills the link, "
                              f"got {self.link_mbit:g}")
        if self.transport != "lossy_link" and (self.loss_percent or self.link_mbit):
            raise CourseError(f"loss_percent and link_mbit need transport='lossy_link' (a private network "
                              f"link that can lose datagrams); transport={self.transport!r} cannot lose "
                              "on purpose")
        if self.transport == "lossy_link" and self.late_joiner:
            raise CourseError("late_joiner=True runs only on 'shm' or 'udp': on the lossy link both ends "
                              "live in a network namespace of their own, where nothing else tells the "
                              "publisher that discovery is done")

    @property
    def count(self) -> int:
        """How many samples the publisher sends: ``rate_hz * duration_s``, at least 1."""
        return max(1, round(self.rate_hz * self.duration_s))

    def with_changes(self, **changes) -> ExperimentConfig:
        """A copy with the given fields changed (validated again)."""
        return replace(self, **changes)

    def describe(self) -> str:
        """The label, or one made from the fields: 'best effort, keep_last 10, 400 Hz x 1 MiB, shm' (the
        reliability in the words every run label uses: 'reliable' or 'best effort')."""
        if self.label:
            return self.label
        history = "keep_all" if self.history == "keep_all" else f"keep_last {self.depth}"
        parts = [self.reliability.replace("_", " "), self.durability, history,
                 f"{format_rate(self.rate_hz)} x {format_bytes(self.payload_bytes)}"]
        if self.processing_ms:
            parts.append(f"{self.processing_ms:g} ms/sample")
        if self.transport == "lossy_link":
            limit = f" {self.link_mbit:g} Mbit/s" if self.link_mbit else ""
            parts.append(f"link {self.loss_percent}% loss{limit}")
        else:
            parts.append(self.transport)
        if self.late_joiner:
            parts.append("late joiner")
        return ", ".join(parts)

    def qos_dict(self) -> dict:
        """The QoS of both ends as a dict for :func:`course_helpers.core.qos_dict.qos_from_dict`
        (JSON values, so that it can be passed to the publisher's process)."""
        return {"reliability": self.reliability, "durability": self.durability,
                "history": self.history, "depth": self.depth}


def _check_choice(name: str, value, allowed) -> None:
    if value not in allowed:
        raise CourseError(f"{name} must be one of {', '.join(repr(a) for a in allowed)}; got {value!r}")


def _check_number(name: str, value, low: float, high: float, unit: str) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CourseError(f"{name} must be a number from {low:g} to {high:g} {unit}, got {value!r}")
    if not low <= value <= high:
        raise CourseError(f"{name} must be from {low:g} to {high:g} {unit}, got {value:g}")


# ---------------------------------------------------------------------- presets
PRESETS: dict[str, dict] = {
    "best-effort vs reliable under load": {
        "what": "300 samples of 1 MiB at 400 Hz, more than this machine moves in time; KEEP_LAST 300 so "
                "the writer holds the whole burst. Best-effort drops what does not fit; reliable resends "
                "what the reader missed, later but complete.",
        "configs": [
            ExperimentConfig(reliability="best_effort", depth=300, rate_hz=400, payload_bytes=2**20,
                             duration_s=0.75, label="best effort, 1 MiB @ 400 Hz"),
            ExperimentConfig(reliability="reliable", depth=300, rate_hz=400, payload_bytes=2**20,
                             duration_s=0.75, label="reliable, 1 MiB @ 400 Hz"),
        ],
    },
    "depth 1 vs 100, slow subscriber": {
        "what": "200 Hz, the subscriber needs 10 ms per sample: with depth 1 the reader keeps only "
                "the newest sample and the others are overwritten; depth 100 queues them.",
        "configs": [
            ExperimentConfig(reliability="reliable", depth=1, rate_hz=200, payload_bytes=1024,
                             processing_ms=10, duration_s=1.0, label="depth 1, 10 ms/sample"),
            ExperimentConfig(reliability="reliable", depth=100, rate_hz=200, payload_bytes=1024,
                             processing_ms=10, duration_s=1.0, label="depth 100, 10 ms/sample"),
        ],
    },
    "late joiner: volatile vs transient_local": {
        "what": "The publisher sends 20 samples, then the subscriber joins: VOLATILE gets none of "
                "them, TRANSIENT_LOCAL gets the last `depth` the writer kept.",
        "configs": [
            ExperimentConfig(durability="volatile", depth=10, rate_hz=100, duration_s=0.2,
                             late_joiner=True, label="late joiner, volatile"),
            ExperimentConfig(durability="transient_local", depth=10, rate_hz=100, duration_s=0.2,
                             late_joiner=True, label="late joiner, transient_local"),
        ],
    },
    "Wi-Fi link, 10 % loss": {
        "what": "Both ends on a private network link that drops 10 % of the data datagrams, as a busy "
                "Wi-Fi link can: 400 samples of 1 KiB at 400 Hz, KEEP_LAST 400 so that no queue "
                "overflows. Best effort delivers about 90 % of them; reliable repairs every loss, and "
                "the repairs show in its p99 latency.",
        "configs": [
            ExperimentConfig(reliability="best_effort", depth=400, rate_hz=400, duration_s=1.0,
                             transport="lossy_link", loss_percent=10, label="best effort, 10 % loss"),
            ExperimentConfig(reliability="reliable", depth=400, rate_hz=400, duration_s=1.0,
                             transport="lossy_link", loss_percent=10, label="reliable, 10 % loss"),
        ],
    },
    "KEEP_ALL back-pressure": {
        "what": "KEEP_ALL reliable, a slow subscriber: the writer may not drop anything, its history "
                "fills, and publish() fails (RCLError), counted per run.",
        "configs": [
            ExperimentConfig(reliability="reliable", history="keep_all", depth=None, rate_hz=5000,
                             payload_bytes=16, processing_ms=100, duration_s=4.0,
                             label="keep_all, 5000 Hz, 100 ms/sample"),
        ],
    },
}


def preset(name: str) -> list[ExperimentConfig]:
    """The configurations of the preset ``name`` (a key of ``PRESETS``); CourseError for another name."""
    try:
        return list(PRESETS[name]["configs"])
    except KeyError:
        raise CourseError(f"unknown preset {name!r}; presets: {', '.join(sorted(PRESETS))}") from None
