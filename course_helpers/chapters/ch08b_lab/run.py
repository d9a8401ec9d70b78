"""One QoS lab experiment: ``run_experiment(config) -> ExperimentResult``.

* the publisher (:class:`LabPublisher`) runs in a CHILD PROCESS, so every sample crosses a
  real Fast DDS transport (shared memory or UDP loopback); it reports its progress and a
  final summary over the process channel (``child.last('progress')``, ``child.last('summary')``);
* the subscriber (:class:`LabSubscriber`) runs in the kernel's runtime and counts what
  arrives, the sequence gaps, the ``message_lost`` events and the latency; on the lossy link
  (:mod:`.link`) both ends are child processes in a network namespace of their own, and the
  subscriber (:class:`ReportingLabSubscriber`) reports its counts over its process channel;
* the publisher counts ``publish()`` failures (``RCLError`` when a KEEP_ALL writer's
  history is full), so back-pressure is an error counted per run, not a crash.

Nothing is simulated: if a configuration loses nothing, the result says so.
"""

from __future__ import annotations

import os
import threading
import time
from array import array
from dataclasses import dataclass, field

from course_helpers.chapters.ch08b_lab.config import ExperimentConfig
from course_helpers.chapters.ch08b_lab.link import SUBSCRIBER_LABEL, RemoteSubscriber, link_env, lossy_link
from course_helpers.chapters.ch08b_lab.publisher import CHILD_LABEL, LabPublisher
from course_helpers.chapters.ch08b_lab.results import (
    ExperimentResult,
    Snapshot,
    latency_percentiles,
    loopback_bytes,
)
from course_helpers.chapters.ch08b_lab.subscriber import LabSubscriber, ReportingLabSubscriber
from course_helpers.core import processes
from course_helpers.core.dds_config import udp_loopback_env
from course_helpers.core.errors import CourseError
from course_helpers.core.machine_load import LoadMeter
from course_helpers.core.runtime import get_runtime
from course_helpers.core.spawning import CHILD_HANG_S
from course_helpers.core.waiting import poll_until

MATCH_TIMEOUT_S = CHILD_HANG_S  # bounds a hang: child start (Python + rclpy import) plus discovery
_IDLE_END_S = 0.5  # after the publisher is done, end when nothing arrived for this long
# Reliable, once every sample is acknowledged: the rest is in this process's reader queue (or was
# dropped from a shallow writer history); a busy executor may take a moment to hand it over.
_ACKED_IDLE_END_S = 2.0
_RELIABLE_IDLE_END_S = 3.5  # a late joiner that got nothing yet: one Fast DDS heartbeat period (3 s) and more
_LATE_JOIN_LISTEN_S = 1.0  # a matched late joiner listens this long after its last sample
_DRAIN_LIMIT_S = 2.0  # best effort: after the publisher is done, wait at most this long for the rest
# Reliable: a run ends when the writer says every sample is acknowledged. A repair waits for a
# heartbeat (every 3 s by default), and on a busy machine a burst can need many rounds of them (up
# to a minute was measured beside a CPU hog and another kernel's nodes). The lab waits as long as
# repaired samples keep arriving, at most _RELIABLE_LIMIT_S after the last sample was sent, and
# gives up when none arrived for _RELIABLE_STALL_S (several heartbeat periods). Stop ends it sooner.
_RELIABLE_LIMIT_S = 90.0
_RELIABLE_STALL_S = 20.0
# A subscriber that works processing_ms on each sample needs at least that long per queued sample:
# when the queue could not drain within this many seconds, the run ends with the rest in flight.
_BACKLOG_LIMIT_S = 6.0
_START_POLL_S = 0.02  # while the publisher starts: how often to look for its first report

_run_lock = threading.Lock()
_run_counter = 0


def run_experiment(config: ExperimentConfig, progress=None, stop_event: threading.Event | None = None,
                   progress_period_s: float = 0.1, drop_log_group: int | None = None) -> ExperimentResult:
    """Run one real experiment and return what it measured.

    Args:
        config: what to run.
        progress: called about every ``progress_period_s`` seconds (in this thread) with a
            :class:`Snapshot` of the run so far; None for no calls.
        stop_event: setting it ends the run: the publisher's process is stopped within a
            second and the result has ``stopped=True``.
        progress_period_s: seconds between snapshots (> 0).
        drop_log_group: on the lossy link, also log each datagram it drops to this netfilter log
            group (a capture of the run reads it: chapter 08c).

    Returns:
        An :class:`ExperimentResult`; its ``timeline`` holds every snapshot and a final one.

    Only one experiment runs at a time per kernel (a second call raises CourseError).
    """
    if not isinstance(config, ExperimentConfig):
        raise CourseError(f"run_experiment() takes an ExperimentConfig, got {type(config).__name__}")
    if progress_period_s <= 0:
        raise CourseError(f"progress_period_s must be > 0, got {progress_period_s!r}")
    if not _run_lock.acquire(blocking=False):
        raise CourseError("another QoS lab experiment is running in this kernel; stop it first "
                          "(the panel's Stop button, or set its stop_event).")
    try:
        return _run(config, progress, stop_event or threading.Event(), progress_period_s, drop_log_group)
    finally:
        _run_lock.release()


@dataclass
class _RunState:
    config: ExperimentConfig
    topic: str
    sub: LabSubscriber | RemoteSubscriber | None = None
    progress_line: dict | None = None  # the publisher's latest 'progress' report
    summary: dict | None = None  # its 'summary' report, once it has sent everything
    send_start: float | None = None  # when the publisher started sending (monotonic s)
    summary_at: float | None = None  # when this kernel saw the summary (monotonic s)
    acked_at: float | None = None  # when it saw that the reader had acknowledged every sample
    matched_at: float | None = None  # late joiner: when its subscription matched the writer
    stopped: bool = False
    cut_short: bool = False
    end_reason: str = ""  # why the run ended with samples still to come ('' when it did not)
    timeline: list = field(default_factory=list)
    writer_gid: str = ""  # the publisher's 'writer' report

    def add_subscriber(self, rt, joins_before_first_sample: bool) -> None:
        c = self.config
        self.sub = rt.add(LabSubscriber, self.topic, c.qos_dict(), c.processing_ms, joins_before_first_sample,
                          console=False)


def _run(config: ExperimentConfig, progress, stop_event: threading.Event,
         period_s: float, drop_log_group: int | None) -> ExperimentResult:
    global _run_counter
    _run_counter += 1
    rt = get_runtime()
    # A fresh topic per run: nothing is left from older runs.
    run = _RunState(config, topic=f"/qos_lab/run_{os.getpid()}_{_run_counter}")
    wall_start = time.monotonic()
    meter = LoadMeter()
    link = None
    if config.transport == "lossy_link":
        link = lossy_link(config.loss_percent, config.link_mbit, log_group=drop_log_group)
    counter_pid = link.pid if link is not None else "self"  # whose loopback interface carries the samples
    lo_start = loopback_bytes(counter_pid)
    child = None
    try:
        # 'shm': the child inherits the kernel's set-up, and Fast DDS uses shared memory between
        # processes of one machine; 'udp' and the link: UDP on 127.0.0.1 only (loopback_bytes shows it).
        env = {}
        if config.transport == "udp":
            env = udp_loopback_env(rt.log_dir)
        elif link is not None:
            env = link_env(rt.log_dir)
        params = {"topic": run.topic, "qos": config.qos_dict(), "rate_hz": config.rate_hz,
                  "payload_bytes": config.payload_bytes, "count": config.count,
                  "wait_for_subscriber": not config.late_joiner,
                  "wait_for_node": rt.graph.get_fully_qualified_name() if config.late_joiner else None,
                  "deadline_s": _send_deadline_s(config)}
        if link is not None:  # both ends on the link, the subscriber first; the publisher waits for its word
            params["ready_topic"] = f"{run.topic}_ready"
            sub_argv = processes.python_target_argv(ReportingLabSubscriber, {
                "topic": run.topic, "qos": config.qos_dict(), "processing_ms": config.processing_ms,
                "ready_topic": params["ready_topic"]})
            run.sub = RemoteSubscriber(link.start(SUBSCRIBER_LABEL, sub_argv, env=env))
            child = link.start(CHILD_LABEL, processes.python_target_argv(LabPublisher, params), env=env)
        else:
            if not config.late_joiner:  # subscribe first, so the publisher can wait until it is matched
                run.add_subscriber(rt, joins_before_first_sample=True)
            child = rt.spawn(CHILD_LABEL, LabPublisher, params=params, env=env)
        if _wait_until_sending(child, stop_event, config, run.sub):
            run.send_start = child.channel.stamped("progress")[0][0]  # the child's clock is ours
            _follow(rt, run, child, progress, stop_event, period_s)
        else:
            run.stopped, run.end_reason = True, "stopped before the samples flowed"
    finally:
        if isinstance(run.sub, RemoteSubscriber):
            run.sub.child.request_stop()  # both ends of the link stop together
        if child is not None:
            child.stop(grace_s=0.5)
            rt.stop_child(CHILD_LABEL)
            if run.summary is None:  # stopped early: what the child had reported until then
                run.progress_line, run.summary = child.last("progress"), child.last("summary")
            run.writer_gid = (child.last("writer") or {}).get("gid", "")
        if isinstance(run.sub, RemoteSubscriber):
            run.sub.finish()
        elif run.sub is not None:
            rt.remove(run.sub)
    return _result(config, run, time.monotonic() - wall_start, loopback_bytes(counter_pid) - lo_start,
                   meter.finish())


def _wait_until_sending(child, stop_event: threading.Event, config: ExperimentConfig, sub) -> bool:
    """Wait for the publisher's first 'progress' report (it has started sending): True.

    Returns False if ``stop_event`` is set first; raises CourseError if the process ends or the
    two sides do not connect within MATCH_TIMEOUT_S.
    """
    remote = sub.child if isinstance(sub, RemoteSubscriber) else None
    poll_until(lambda: (stop_event.is_set() or child.last("progress") is not None or not child.alive
                        or (remote is not None and not remote.alive)), MATCH_TIMEOUT_S, period=_START_POLL_S)
    if stop_event.is_set():
        return False
    if child.last("progress") is not None:
        return True
    if not child.alive:
        raise child.failure("it started sending")
    if remote is not None and not remote.alive:
        raise remote.failure("the publisher started sending")
    raise CourseError(
        f"the publisher and subscriber did not connect within {MATCH_TIMEOUT_S:g} s (transport "
        f"{config.transport!r}). Publisher output:\n{child.output_tail()}")


def _follow(rt, run: _RunState, child, progress, stop_event: threading.Event, period_s: float) -> None:
    """Every ``period_s``: a snapshot for ``progress``, until nothing more is to come or ``stop_event``."""
    config = run.config
    # One wake-up per period (not the usual one every few ms): a thread that wakes often takes the
    # GIL from the executor thread that receives the samples, and on a busy machine it shows.
    while not poll_until(stop_event.is_set, period_s, period=period_s):
        now = time.monotonic()
        run.progress_line, run.summary = child.last("progress"), child.last("summary")
        if run.acked_at is None and child.last("acked") is not None:
            run.acked_at = now
        if run.summary is not None and run.summary_at is None:
            run.summary_at = now
            if config.late_joiner:  # everything is sent: now the subscriber joins
                run.add_subscriber(rt, joins_before_first_sample=False)
        snap = _snapshot(run.sub, run.progress_line, run.summary, now - run.send_start)
        run.timeline.append(snap)
        if progress is not None:
            progress(snap)
        if run.summary_at is None:
            if not child.alive:
                raise child.failure("it had sent every sample")
            continue
        if _finished(run, now, config):
            return
        reason = "" if config.late_joiner else _give_up(run, now, config)
        if reason:
            run.cut_short, run.end_reason = True, reason  # samples were still coming: in flight, not lost
            return
    run.stopped, run.end_reason = True, "stopped before it finished"


def _send_deadline_s(config) -> float:
    """How long the publisher may take to send everything (back-pressure slows it down)."""
    return config.duration_s * 1.25 + 1.0


def _finished(run, now, config) -> bool:
    """True when nothing more is to come."""
    sub = run.sub
    if config.late_joiner:
        if run.matched_at is None:
            if sub.subscription.get_publisher_count() == 0:  # not matched with the writer yet
                if now - run.summary_at > MATCH_TIMEOUT_S:
                    raise CourseError(f"the late joiner did not match the publisher within "
                                      f"{MATCH_TIMEOUT_S:g} s")
                return False
            run.matched_at = now
        if sub.delivered == 0:  # nothing yet: give a repair a chance (one heartbeat period)
            return now - run.matched_at >= _RELIABLE_IDLE_END_S
        return now - max(run.matched_at, sub.last_arrival) >= _LATE_JOIN_LISTEN_S
    if run.summary["published"] == 0:
        return True
    if sub.last_seq is not None and sub.last_seq >= run.summary["published"]:
        return True  # the last sample that was sent has arrived
    # The writer says the reader has acknowledged every sample (at once for best-effort): what has
    # not been delivered a moment after that never will be. Until then a reliable writer still
    # repairs what the reader missed, however slowly on a busy machine; only _give_up ends that
    # wait early, and then the missing samples count as in flight, not lost.
    if run.acked_at is None:
        return False
    idle = _ACKED_IDLE_END_S if config.reliability == "reliable" else _IDLE_END_S
    return now - max(run.acked_at, sub.last_arrival) > idle


def _give_up(run, now, config) -> str:
    """After the publisher is done: why to stop waiting for the samples still to come ('' to wait on)."""
    waited = now - run.summary_at
    limit = _RELIABLE_LIMIT_S if config.reliability == "reliable" else _DRAIN_LIMIT_S
    if waited > limit:
        what = "acknowledgements and repairs" if config.reliability == "reliable" else "queued samples"
        return f"the lab stopped waiting for {what} {limit:g} s after the last sample was sent"
    quiet_s = now - max(run.summary_at, run.sub.last_arrival)
    if config.reliability == "reliable" and quiet_s > _RELIABLE_STALL_S:
        return f"no sample arrived for {_RELIABLE_STALL_S:g} s: the repairs had stopped coming"
    if config.processing_ms:
        remaining = run.summary["published"] - (run.sub.last_seq or 0)
        needed_s = remaining * config.processing_ms / 1000  # the subscriber's own time, at least
        if needed_s > _BACKLOG_LIMIT_S - waited:
            return (f"queued for a subscriber that needs {config.processing_ms:g} ms per sample: the rest "
                    f"would take at least {needed_s:.0f} s more")
    return ""


def _snapshot(sub, progress_line, summary, t) -> Snapshot:
    report = summary or progress_line or {}
    published = report.get("published", 0)
    if sub is None:
        delivered = gaps = events = 0
        lat = latency_percentiles(array("q"))
    else:
        delivered, gaps, events = sub.delivered, sub.gaps, sub.lost_events
        lat = sub.latency()
        if summary is None and sub.last_seq:  # the child reports every 0.1 s; a sample that
            published = max(published, sub.last_seq)  # arrived with number N proves N were sent
    return Snapshot(t=round(t, 4), delivered=delivered, lost_by_sequence=gaps, lost_events=events,
                    published=published, publish_errors=report.get("publish_errors", 0),
                    latency_p50_ms=lat["p50"], latency_p90_ms=lat["p90"], latency_p99_ms=lat["p99"])


def _result(config, run, wall_s, lo_bytes, machine) -> ExperimentResult:
    report = run.summary or run.progress_line or {}
    sub = run.sub
    published = int(report.get("published", 0))
    gaps = in_flight = 0
    if sub is not None:
        gaps = sub.gaps
        tail = max(0, published - (sub.last_seq or 0)) if not config.late_joiner else 0
        if run.summary is None or run.stopped or run.cut_short:
            in_flight = tail  # the run ended while samples could still arrive: not counted as lost
        else:
            gaps += tail  # nothing more arrived: the samples after the last one that did are lost
    lat = sub.latency() if sub is not None else latency_percentiles(array("q"))
    events = sub.lost_events if sub is not None else 0
    delivered = sub.delivered if sub is not None else 0
    errors = int(report.get("publish_errors", 0))
    t_end = time.monotonic() - run.send_start if run.send_start is not None else 0.0
    final = Snapshot(t=round(t_end, 4), delivered=delivered, lost_by_sequence=gaps, lost_events=events,
                     published=published, publish_errors=errors, in_flight=in_flight,
                     latency_p50_ms=lat["p50"], latency_p90_ms=lat["p90"], latency_p99_ms=lat["p99"],
                     done=True)
    return ExperimentResult(
        config=config, planned=config.count, published=published, publish_errors=errors,
        not_attempted=config.count - int(report.get("attempted", 0)), delivered=delivered,
        lost_by_sequence=gaps, lost_events=events, in_flight=in_flight, latency_ms=lat,
        send_time_s=float(report.get("elapsed_s", 0.0)), wall_time_s=wall_s, loopback_bytes=lo_bytes,
        stopped=run.stopped, first_error=report.get("first_error", ""),
        first_seq=sub.first_seq if sub is not None else None, timeline=[*run.timeline, final],
        end_reason=run.end_reason if in_flight else "", machine=machine, writer_gid=run.writer_gid)

