"""Checker of chapter 08b (the QoS lab): choose a QoS that meets a loss and a latency target.

The task: a sensor driver sends a burst of :data:`BURST_SAMPLES` samples at 200 Hz to a
subscriber that needs 10 ms per sample, so samples arrive twice as fast as they are handled.
The student picks the QoS profile of both ends; :func:`check_burst_qos` runs the real lab
experiment with it (the publisher in a child process, the subscriber in this process, the
samples over Fast DDS shared memory) and checks the targets.

The targets leave room for a busy machine: with a queue that holds the burst nothing can be
lost (the subscriber is slow, not gone), and the last sample waits about
``BURST_SAMPLES * 10 ms - 0.3 s`` = 0.3 s, far below :data:`MAX_P99_MS` even when every
sample takes twice as long to handle.
"""

from __future__ import annotations

from rclpy.qos import QoSProfile

from course_helpers.chapters.ch08b_lab import ExperimentConfig, run_experiment
from course_helpers.checks import CheckReport
from course_helpers.core.errors import CourseError
from course_helpers.core.qos_dict import qos_to_dict

BURST_RATE_HZ = 200.0  # samples per second the driver sends
BURST_SAMPLES = 60  # one burst: 0.3 s at 200 Hz
PROCESSING_MS = 10.0  # what the subscriber needs per sample [ms]
PAYLOAD_BYTES = 1024
MAX_LOST = 0  # the loss target: every sample of the burst is handled
MAX_P99_MS = 2000.0  # the latency target: 99 % of the samples handled within this [ms]
_POLICY_NAMES = {"deadline_s": "deadline", "lifespan_s": "lifespan", "lease_s": "liveliness_lease_duration",
                 "liveliness": "liveliness"}


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
                            duration_s=BURST_SAMPLES / BURST_RATE_HZ, label="your QoS, the burst")


def check_burst_qos(qos: QoSProfile, max_lost: int = MAX_LOST, max_p99_ms: float = MAX_P99_MS) -> CheckReport:
    """Exercise 08b: run the burst with ``qos`` on both ends and check the loss and latency targets.

    ``max_lost`` and ``max_p99_ms`` are the targets (the exercise's by default). Returns the
    CheckReport; its details hold the measured numbers.
    """
    report = CheckReport("Exercise 08b - a QoS for a burst to a slow subscriber")
    config = report.run("the QoS is a profile the lab can run", lambda: burst_config(qos),
                        hint="burst_qos = QoSProfile(reliability=..., history=..., depth=...) with the "
                             "policies of rclpy.qos; KEEP_LAST needs a depth from 1 to 1000.")
    if config is None:
        return report
    report.add("the QoS is a profile the lab can run", True)
    result = report.run("the experiment ran", lambda: run_experiment(config),
                        hint="Run the cell again; if it fails again, the error says what went wrong.")
    if result is None:
        return report
    sent = config.count
    report.add(f"the driver sent all {sent} samples", result.published == sent,
               f"sent {result.published}", "publish() failed: the lab's summary says why.")
    lost = result.lost_by_sequence + result.in_flight
    report.add(f"loss target: at most {max_lost} of the {sent} samples lost", lost <= max_lost,
               f"handled {result.delivered}, lost {lost}",
               "The subscriber is slow, not gone: samples are lost when its queue is full and a new one "
               "replaces the oldest. Reliability cannot bring those back; a history that holds the "
               "whole burst can.")
    p99 = result.latency_ms["p99"]
    report.add(f"latency target: p99 at most {max_p99_ms:g} ms", p99 is not None and p99 <= max_p99_ms,
               "nothing arrived" if p99 is None else f"p99 {p99:.0f} ms",
               "Every queued sample waits for the ones before it: a queue far longer than the burst "
               "adds nothing, and the wait grows with what is queued.")
    return report
