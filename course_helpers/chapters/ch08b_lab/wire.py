"""Reliability on the wire (notebook 08c): a lossy-link run captured, and its repairs read from RTPS.

:func:`capture_run` runs one lab experiment on the lossy link (:mod:`.link`) with ``dumpcap``
capturing the link's user traffic (UDP to odd ports, where the loss rule acts) and the drop log
of that rule (:mod:`course_helpers.core.rtps_capture`), then keeps the submessages of the run's
writer: the DATA, HEARTBEAT and GAP it sent, and the ACKNACKs its reader sent back. Which writer is
the run's comes from the publisher itself (it reports its GUID).

How Fast DDS 2.14 repairs a lost sample (``StatefulWriter``, ``StatefulReader``, ``WriterProxy``):

* the reader sends an ACKNACK naming missing samples only when its heartbeat-response timer fires
  (``WriterProxy::perform_heartbeat_response``), and only a HEARTBEAT (re)starts that timer
  (``WriterProxy::process_heartbeat``), ``heartbeatResponseDelay`` (5 ms) before it fires; the
  reader's other ACKNACK, the preemptive one sent before its first HEARTBEAT, names nothing;
* the writer sends a sample again only once an ACKNACK has asked for it
  (``ReaderProxy::requested_changes_set``), when its nack-response timer fires
  (``StatefulWriter::perform_nack_response``): ``nackResponseDelay`` (5 ms) after the ACKNACK that
  armed it, which may be an earlier one (restarting an armed ``TimedEvent`` keeps its time), so a
  repair can follow its own ACKNACK, and its loss, by less; a sample no longer in its history gets a
  GAP instead;
* a best-effort reader acknowledges nothing, and a best-effort writer sends nothing twice.

So each repaired sample has, in this order: a HEARTBEAT that reached the reader, an ACKNACK naming
the sample that reached the writer, and a copy of the sample that arrived (:class:`Repair`). A
second HEARTBEAT may make the reader ask again while the copy is on its way, so the ACKNACK taken is
the first after the last lost copy. The
HEARTBEAT's range need not reach the lost number: the reader also learns that a number is missing
when a later sample arrives. How long a repair takes is mostly the wait for the next HEARTBEAT (the
link's writers send one every ``HEARTBEAT_S``, and piggy-back one on data when their history is full
or a send buffer's worth has gone out): a measurement, printed, never asserted.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

from course_helpers.chapters.ch08b_lab.config import ExperimentConfig
from course_helpers.chapters.ch08b_lab.link import link_unavailable_reason, lossy_link
from course_helpers.chapters.ch08b_lab.results import ExperimentResult
from course_helpers.chapters.ch08b_lab.run import run_experiment
from course_helpers.core import rtps_capture
from course_helpers.core.errors import CourseError
from course_helpers.core.rtps_capture import DROP_LOG_GROUP, ODD_PORTS, Submessage

CAPTURE_LABEL = "qos_lab_capture"
COUNTED = ("DATA", "HEARTBEAT", "ACKNACK", "GAP")
HEARTBEAT_RESPONSE_DELAY_S = 0.005  # Fast DDS 2.14 ReaderTimes default (the link's profile keeps it)
NACK_RESPONSE_DELAY_S = 0.005  # Fast DDS 2.14 WriterTimes default (the link's profile keeps it)


def wire_unavailable_reason() -> str | None:
    """None if a run can be captured here; else one line: what is missing and how to get it."""
    return rtps_capture.unavailable_reason() or link_unavailable_reason()


@dataclass(frozen=True)
class Repair:
    """How one lost sample came back: the copies the link dropped, then HEARTBEAT -> ACKNACK -> DATA.

    ``resent``: the first copy of the sample that arrived; ``acknack``: the ACKNACK that asked for it,
    the first naming ``seq`` that reached the writer after the last lost copy (if the capture shows none
    there, the last one before ``resent``); ``heartbeat``: the writer's last HEARTBEAT that reached the
    reader before that ACKNACK (the one whose response timer sent it). None where a link is missing.
    """

    seq: int
    lost: tuple[Submessage, ...]
    heartbeat: Submessage | None
    acknack: Submessage | None
    resent: Submessage

    @property
    def in_order(self) -> bool:
        """True when the chain is whole: a HEARTBEAT, then an ACKNACK naming the sample (after its first
        lost copy), then the copy that arrived. (The HEARTBEAT may come before the lost copy: see the
        module docstring.)"""
        if self.heartbeat is None or self.acknack is None:
            return False
        return (self.heartbeat.frame < self.acknack.frame < self.resent.frame
                and self.lost[0].frame < self.acknack.frame)

    @property
    def waited_s(self) -> float:
        """From the first lost copy to the copy that arrived (the capture's clock)."""
        return self.resent.time - self.lost[0].time



@dataclass
class WireRun:
    """One captured run: the lab's result and its writer's submessages (see the module docstring)."""

    result: ExperimentResult
    capture_bytes: int
    submessages: list[Submessage] = field(repr=False)

    @property
    def config(self) -> ExperimentConfig:
        return self.result.config

    def data(self, seq: int | None = None) -> list[Submessage]:
        """The writer's DATA submessages (of sample ``seq`` only, if given), in capture order."""
        return [s for s in self.submessages if s.kind == "DATA" and seq in (None, s.seq)]

    @property
    def lost(self) -> list[int]:
        """Sequence numbers whose first copy the link dropped: the samples the reader lacked.

        A sample whose first copy arrived can still be sent again: an ACKNACK may ask for it while that
        copy waits in the reader's socket (a busy reader). The link dropping such a copy loses the reader
        nothing, so it is no loss and needs no repair; :attr:`resent` still counts it."""
        first: dict[int, Submessage] = {}
        for copy in self.data():
            first.setdefault(copy.seq, copy)
        return sorted(seq for seq, copy in first.items() if copy.dropped)

    @property
    def repairs(self) -> list[Repair]:
        """A :class:`Repair` for each lost sample that arrived later, by sequence number."""
        found = []
        for seq in self.lost:
            copies = self.data(seq)
            arrived = next((s for s in copies if not s.dropped), None)
            if arrived is None:
                continue
            lost = tuple(s for s in copies if s.dropped and s.frame < arrived.frame)
            asked = [s for s in self.submessages if s.kind == "ACKNACK" and not s.dropped and seq in s.numbers
                     and s.frame < arrived.frame]
            after_loss = [s for s in asked if s.frame > lost[-1].frame]
            acknack = after_loss[0] if after_loss else (asked[-1] if asked else None)
            heartbeat = None
            if acknack is not None:
                heartbeat = _last(self.submessages, acknack.frame, "HEARTBEAT",
                                  lambda s, reader=acknack.src: s.dst in ("", reader))
            found.append(Repair(seq, lost, heartbeat, acknack, arrived))
        return found

    @property
    def unrepaired(self) -> list[int]:
        """Lost samples of which no copy arrived."""
        return [seq for seq in self.lost if all(s.dropped for s in self.data(seq))]

    @property
    def resent(self) -> int:
        """DATA copies sent beyond the first of each sample."""
        return len(self.data()) - len({s.seq for s in self.data()})

    def counts(self) -> dict:
        """Submessages of the writer and its reader by kind: ``{kind: (sent, dropped by the link)}``."""
        sent = Counter(s.kind for s in self.submessages)
        dropped = Counter(s.kind for s in self.submessages if s.dropped)
        return {kind: (sent[kind], dropped[kind]) for kind in COUNTED}

    def all_repaired_in_order(self) -> bool:
        """Every lost sample arrived, each after a HEARTBEAT and an ACKNACK naming it (reliable)."""
        return not self.unrepaired and all(r.in_order for r in self.repairs)

    def nothing_repaired(self) -> bool:
        """No ACKNACK, no HEARTBEAT, no sample sent twice: what the link dropped stays lost (best effort)."""
        counts = self.counts()
        return counts["ACKNACK"][0] == counts["HEARTBEAT"][0] == self.resent == 0 and not self.repairs

    def summary(self) -> str:
        """Two lines: the run, and its submessages."""
        counts = self.counts()
        line = ", ".join(f"{kind} {sent}" + (f" ({dropped} dropped)" if dropped else "")
                         for kind, (sent, dropped) in counts.items())
        return (f"{self.result.summary()}\n  on the wire: {line}; {self.resent} DATA sent again; "
                f"{len(self.lost)} samples lost (first copy dropped), {len(self.repairs)} repaired, "
                f"{len(self.unrepaired)} never arrived (capture {self.capture_bytes / 1e3:.0f} kB)")


def _last(records: list[Submessage], before_frame: int, kind: str, wanted) -> Submessage | None:
    """The last record of ``kind`` that arrived (was not dropped) before frame ``before_frame`` and for
    which ``wanted`` holds."""
    for record in reversed(records):
        if record.frame < before_frame and record.kind == kind and not record.dropped and wanted(record):
            return record
    return None


def runs_submessages(records: list[Submessage], writer_gid: str) -> list[Submessage]:
    """The records of one writer (32 hex digits): what it sent, and what readers sent it."""
    return [s for s in records if s.writer_guid == writer_gid]


def capture_run(config: ExperimentConfig) -> WireRun:
    """Run ``config`` (on the lossy link) with a capture of the link; the :class:`WireRun`.

    The capture keeps the link's user traffic (UDP to odd ports) and its drop log; it stops
    with the run, also when the run fails. Raises CourseError saying what is missing where the
    tools or namespaces are not available, or for a configuration that is not on the link.
    """
    if not isinstance(config, ExperimentConfig) or config.transport != "lossy_link":
        raise CourseError("capture_run() takes an ExperimentConfig with transport='lossy_link' (the link is "
                          f"the private network the capture listens to), got {config!r}")
    reason = wire_unavailable_reason()
    if reason is not None:
        raise CourseError(f"capturing a run needs tshark and a network namespace: {reason}")
    link = lossy_link(config.loss_percent, config.link_mbit, log_group=DROP_LOG_GROUP)
    capture = rtps_capture.start_capture(link, CAPTURE_LABEL, ODD_PORTS, DROP_LOG_GROUP)
    try:
        result = run_experiment(config, drop_log_group=DROP_LOG_GROUP)
    finally:
        capture.stop()
    if not result.writer_gid:
        raise CourseError("the publisher did not report its writer's GUID, so its submessages cannot be "
                          "told from the others in the capture")
    return WireRun(result, capture.size_bytes, runs_submessages(capture.submessages(), result.writer_gid))
