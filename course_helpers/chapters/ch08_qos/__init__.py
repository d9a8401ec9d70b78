"""Chapter 08a, Quality of Service, one policy at a time, on real publishers and subscriptions.

The notebook writes the nodes of each lesson itself (QoS profiles, event callbacks as methods);
this package runs schedules and child processes around them and draws what they recorded.
Every ``demo_*`` function runs real nodes (in the kernel, or in a child process when the point
needs a real transport or a process that can be killed), records what arrived and which QoS
events fired, and returns the data; the ``plot_*`` functions draw it.

* :mod:`.reliability` - best effort against reliable, with the ``message_lost`` event;
* :mod:`.history` - a burst into a subscription that is not being spun;
* :mod:`.durability` - late joiners, TRANSIENT_LOCAL and lifespan;
* :mod:`.deadline` - offered and requested deadline missed;
* :mod:`.liveliness` - a killed publisher process, a quiet MANUAL_BY_TOPIC publisher;
* :mod:`.compatibility` and :mod:`.explorer` - whether a publisher and a subscription connect;
* :mod:`.profiles` - the predefined profiles side by side;
* :mod:`.publishers` - the publishers the demos run in child processes;
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
    rclpy_verdict,
    try_pair,
)
from course_helpers.chapters.ch08_qos.deadline import (
    DeadlineResult,
    demo_deadline,
    pause_talker,
    plot_deadline,
)
from course_helpers.chapters.ch08_qos.durability import (
    LifespanResult,
    demo_durability,
    demo_lifespan,
    plot_lifespan,
)
from course_helpers.chapters.ch08_qos.exercise import (
    HEARTBEAT_QOS,
    ODOM_QOS,
    ROBOT_CMD_QOS,
    OdomSensor,
    RobotCmdPublisher,
    ScheduledHeartbeat,
)
from course_helpers.chapters.ch08_qos.explorer import compatibility_explorer
from course_helpers.chapters.ch08_qos.history import demo_history
from course_helpers.chapters.ch08_qos.liveliness import (
    LivelinessResult,
    LivelinessTalker,
    LivelinessWatcher,
    demo_liveliness_kill,
    demo_liveliness_manual,
    plot_liveliness,
)
from course_helpers.chapters.ch08_qos.profiles import PREDEFINED, profiles_table, show_profiles_table
from course_helpers.chapters.ch08_qos.publishers import IntTalker, QosTalker, StreamPublisher
from course_helpers.chapters.ch08_qos.reliability import ReliabilityResult, demo_reliability, plot_reliability
from course_helpers.core.qos_dict import (
    DEFAULT_QOS_DICT,
    describe_qos,
    duration_seconds,
    qos_from_dict,
    qos_to_dict,
    seconds_to_duration,
)
