"""Chapter 08a, Quality of Service, one policy at a time, on real publishers and subscriptions.

The notebook writes the nodes of each lesson itself (QoS profiles, event callbacks as methods).
This package starts the child processes and runs the schedules around them, measures, and draws:

* :mod:`.reliability` - :func:`run_stream` runs a best-effort and reliable stream from another
  process against the notebook's listener;
* :mod:`.history` - :func:`burst_before_spinning` sends a burst while the listener is not spun;
* :mod:`.deadline` - :func:`pause_talker` silences the notebook's talker for a while;
* :mod:`.lifespan` - what a late joiner got of a transient-local publisher's stored messages;
* :mod:`.liveliness` - :func:`watch_after_crash` and :func:`watch_quiet_spell` watch the notebook's
  monitor after its publisher process was killed, and while its publisher goes quiet;
* :mod:`.publishers` - the publishers those run in child processes (the notebook prints them);
* :mod:`.compatibility` and :mod:`.explorer` - whether a publisher and a subscription connect;
* :mod:`.profiles` - the predefined profiles side by side;
* :mod:`.exercise` - the nodes the exercise checkers run against the student's code.

QoS profiles cross process boundaries as plain dicts (:mod:`course_helpers.core.qos_dict`,
re-exported here). The notebook uses ``from course_helpers.chapters import ch08_qos as qos``.
"""

# ruff: noqa: F401  (every import below is a re-export for the notebook)

from course_helpers.chapters.ch08_qos.compatibility import (
    PairResult,
    PolicyVerdict,
    compatibility_report,
    compatible,
    explain_compatibility,
    late_joiner_gets,
    rclpy_verdict,
    try_pair,
)
from course_helpers.chapters.ch08_qos.deadline import DeadlineResult, pause_talker, plot_deadline
from course_helpers.chapters.ch08_qos.exercise import (
    HEARTBEAT_QOS,
    ODOM_QOS,
    ROBOT_CMD_QOS,
    OdomSensor,
    RobotCmdPublisher,
    ScheduledHeartbeat,
)
from course_helpers.chapters.ch08_qos.explorer import compatibility_explorer
from course_helpers.chapters.ch08_qos.history import burst_before_spinning
from course_helpers.chapters.ch08_qos.lifespan import LifespanResult, plot_lifespan
from course_helpers.chapters.ch08_qos.liveliness import (
    LivelinessResult,
    plot_liveliness,
    watch_after_crash,
    watch_quiet_spell,
)
from course_helpers.chapters.ch08_qos.profiles import PREDEFINED, profiles_table, show_profiles_table
from course_helpers.chapters.ch08_qos.publishers import (
    AliveTalker,
    IntTalker,
    LivelinessTalker,
    StreamPublisher,
)
from course_helpers.chapters.ch08_qos.reliability import ReliabilityResult, plot_reliability, run_stream
from course_helpers.core.qos_dict import (
    DEFAULT_QOS_DICT,
    describe_qos,
    duration_seconds,
    qos_from_dict,
    qos_to_dict,
    seconds_to_duration,
)
