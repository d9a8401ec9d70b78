"""Checker of chapter 01 (architecture): a third talker process, and a second crash."""

from __future__ import annotations

from course_helpers.chapters.ch01_architecture import ChatterCounter, count_during
from course_helpers.checks import CheckReport

ENOUGH_MESSAGES = 3  # from talker_c during the listening window (it publishes at 10 Hz)


def check_crash_exercise(rt, counter: ChatterCounter, window_s: float = 1.5) -> CheckReport:
    """Check that a third talker process runs and that talker_b's process was killed.

    Args:
        rt: the kernel's course runtime.
        counter: the running :class:`ChatterCounter` of the notebook.
        window_s: seconds to listen to the counter.

    Returns:
        A :class:`CheckReport` that passes when a child labelled ``talker_c`` runs ``/talker_c``
        (a :class:`NamedTalker`), the child ``talker_b`` has been killed, and ``counter`` hears
        talker_c and nobody else.
    """
    report = CheckReport("Exercise: a third talker, and a second crash")
    children = rt.children()
    c = children.get("talker_c")
    report.add("a child process labelled 'talker_c' is running", c is not None and c.alive,
               "" if c is not None else "no child labelled talker_c",
               hint="rt.spawn('talker_c', NamedTalker, {'name': 'talker_c'}, wait_for='/talker_c')")
    in_graph = "/talker_c" in rt.graph_nodes()
    report.add("node /talker_c is in the ROS graph", in_graph,
               hint="Pass {'name': 'talker_c'} so the node gets that name.")
    b = children.get("talker_b")
    killed = b is not None and not b.alive
    report.add("talker_b's process is dead", killed,
               "" if killed else ("talker_b is still running" if b is not None
                                  else "no child labelled talker_b: start it again, then kill it"),
               hint="Keep the ChildProcess that rt.spawn returned and call its kill() method.")
    heard = count_during(counter, window_s)
    others = sorted(s for s, n in heard.items() if n and s != "talker_c")
    hears_c = heard.get("talker_c", 0) >= ENOUGH_MESSAGES
    report.add("the counter hears talker_c", hears_c, "" if hears_c else "no messages from talker_c",
               hint="talker_c must publish on 'chatter', the topic the counter listens to.")
    report.add("the counter hears nobody else", not others,
               f"still hearing {', '.join(others)}" if others else "",
               hint="Both talker_a and talker_b must be dead.")
    return report
