"""Checker of chapter 08b (the QoS lab): choose a QoS for a burst over a lossy link to a slow subscriber.

The task: a sensor driver sends a burst of :data:`BURST_SAMPLES` samples at 200 Hz to a
subscriber that needs 10 ms per sample, so samples arrive twice as fast as they are handled, over a
private network link that drops :data:`LOSS_PERCENT` % of the data datagrams (the lab's lossy link).
The student picks the QoS profile of both ends; :func:`check_burst_qos` runs the real lab experiment
with it (the publisher in a child process, the subscriber in this process) and checks two targets,
each of which the mechanism decides, not the machine's speed:

* **no sample lost.** The link drops about one datagram in ten: best effort loses that many (it
  keeps all 120 with a probability of 0.9 ** 120, about three in a million), and only RELIABLE
  repairs them. The subscriber is slow, so its queue must also hold the backlog: a KEEP_LAST queue
  shorter than that replaces samples whatever the reliability (a busy machine only makes the backlog
  longer). A queue that holds the whole burst loses nothing, on any machine.
* **a bounded history**: KEEP_LAST, at most twice the burst. KEEP_ALL would let a writer whose
  reader stalls queue without limit; a queue far longer than the burst adds nothing.

The latency is measured and printed, not judged: repairs wait for the writer's heartbeats, and how
long depends on which datagrams the link drops.
"""

from __future__ import annotations

from rclpy.qos import QoSProfile

from course_helpers.chapters.ch08b_lab import ExperimentConfig, link_unavailable_reason, run_experiment
from course_helpers.checks import CheckReport
from course_helpers.core.errors import CourseError
from course_helpers.core.qos_dict import qos_to_dict

BURST_RATE_HZ = 200.0  # samples per second the driver sends
BURST_SAMPLES = 120  # one burst: 0.6 s at 200 Hz
PROCESSING_MS = 10.0  # what the subscriber needs per sample [ms]
PAYLOAD_BYTES = 1024
LOSS_PERCENT = 10  # of the data datagrams, dropped by the link
MAX_DEPTH = 2 * BURST_SAMPLES  # the bounded-history target
_POLICY_NAMES = {"deadline_s": "deadline", "lifespan_s": "lifespan", "lease_s": "liveliness_lease_duration",
                 "liveliness": "liveliness"}
LOSS_TARGET = f"loss target: every one of the {BURST_SAMPLES} samples handled"
BOUNDED = f"the history is bounded: KEEP_LAST with a depth of at most {MAX_DEPTH}"


def burst_config(qos: QoSProfile) -> ExperimentConfig:
    """The lab configuration of the task with the reliability, durability, history and depth of ``qos``.

    Raises CourseError for anything but a QoSProfile, for policies the lab does not run (deadline,
    lifespan, liveliness) and, through ExperimentConfig, for values it does not allow.
    """
    if not isinstance(qos, QoSProfile):
        raise CourseError(f"burst_qos must be a rclpy.qos.QoSProfile, got {type(qos).__name__}")
    values = qos_to_dict(qos)
    unset = {"deadline_s": (0.0,), "lifespan_s": (0.0,), "lease_s": (0.0,),
             "liveliness": ("automatic", "system_default")}
    others = sorted(_POLICY_NAMES[key] for key, allowed in unset.items() if values[key] not in allowed)
    if others:
        raise CourseError(f"this task is about reliability, durability, history and depth; leave "
                         f"{', '.join(others)} unset")
    keep_all = values["history"] == "keep_all"
    return ExperimentConfig(reliability=values["reliability"], durability=values["durability"],
                            history=values["history"], depth=None if keep_all else values["depth"],
                            rate_hz=BURST_RATE_HZ, payload_bytes=PAYLOAD_BYTES, processing_ms=PROCESSING_MS,
                            duration_s=BURST_SAMPLES / BURST_RATE_HZ, transport="lossy_link",
                            loss_percent=LOSS_PERCENT, label="your QoS, the burst")


def check_burst_qos(qos: QoSProfile) -> CheckReport:
    """Exercise 08b: run the burst with ``qos`` on both ends over the lossy link, and check the targets
    (see the module docstring). Returns the CheckReport; its details hold the measured numbers."""
    report = CheckReport("Exercise 08b - a QoS for a burst over a lossy link")
    config = report.run("the QoS is a profile the lab can run", lambda: burst_config(qos),
                        hint="burst_qos = QoSProfile(reliability=..., history=..., depth=...) with the "
                             "policies of rclpy.qos; KEEP_LAST needs a depth from 1 to 1000.")
    if config is None:
        return report
    report.add("the QoS is a profile the lab can run", True)
    bounded = config.history == "keep_last" and config.depth <= MAX_DEPTH
    report.add(BOUNDED, bounded, "" if bounded else
               ("KEEP_ALL" if config.history == "keep_all" else f"KEEP_LAST {config.depth}"),
               "A queue far longer than the burst adds nothing; KEEP_ALL lets a writer whose reader stalls "
               "queue without limit.")
    missing = link_unavailable_reason()
    if not report.add("the lossy link is available", missing is None, missing or "",
                      "The README's 'Optional parts' says how to allow private network namespaces."):
        return report
    result = report.run("the experiment ran", lambda: run_experiment(config),
                        hint="Run the cell again; if it fails again, the error says what went wrong.")
    if result is None:
        return report
    sent = config.count
    ran = result.published == sent and result.finished
    if not report.add("the experiment ran", ran, "" if ran else
                      f"sent {result.published} of {sent}" + ("" if result.finished else "; NOT FINISHED"),
                      "The lab's summary above says what happened; run the check again."):
        return report
    lost = result.lost_by_sequence + result.in_flight
    p99 = result.latency_ms["p99"]
    measured = f"handled {result.delivered}, lost {lost}" + (f"; p99 latency {p99:.0f} ms (measured)"
                                                            if p99 is not None else "")
    report.add(LOSS_TARGET, lost == 0, measured,
               "Two things lose samples here: the link, which only a resend can undo, and a queue too "
               "short for the backlog of a slow subscriber, which replaces the oldest sample whatever "
               "the reliability.")
    return report
