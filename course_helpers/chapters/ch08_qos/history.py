"""History and depth: what a subscription's reader keeps while nobody takes its messages.

The notebook writes a talker with a ``burst(count)`` method and a listener with one subscription
per history; :func:`burst_before_spinning` runs the schedule: the burst arrives while the
listener's node is not spun, and only then does the executor take what each history kept.
"""

from __future__ import annotations

import time

from course_helpers.core.errors import CourseError
from course_helpers.core.waiting import poll_until

SETTLE_S = 0.2  # s for the burst to reach the readers' histories, and for any extra delivery to show


def burst_before_spinning(rt, listener_class, talker_class, count: int = 20):
    """Build ``listener_class()`` without spinning it, spin ``talker_class()``, let the talker publish
    ``count`` messages with ``talker.burst(count)``, then spin the listener. Both are removed at the end.

    Args:
        rt: the kernel's runtime.
        listener_class: a Node subclass with ``got``, a dict of lists its callbacks append to.
        talker_class: a Node subclass with ``publisher`` and ``burst(count)``.
        count: how many messages the burst sends, 1..1000.

    Returns the listener, whose ``got`` holds what each subscription delivered once spun.
    """
    if not 1 <= count <= 1000:
        raise CourseError(f"count must be 1..1000, got {count}")
    listener = rt.build(listener_class)  # built in the runtime's context, not spun: nobody takes messages
    talker, spun = None, False
    try:
        if not isinstance(getattr(listener, "got", None), dict) or not listener.got:
            raise CourseError(f"{listener_class.__name__} needs self.got, a dict of lists (one per "
                              "subscription) that its callbacks append to")
        talker = rt.add(talker_class, console=False)
        subscriptions = len(list(listener.subscriptions))
        rt.wait_until(lambda: talker.publisher.get_subscription_count() >= subscriptions, 5.0,
                      f"the talker to match the listener's {subscriptions} subscriptions")
        talker.burst(count)
        time.sleep(SETTLE_S)  # delivered into the readers' histories; no callback has run
        rt.add(listener, console=False)
        spun = True
        poll_until(lambda: max(len(got) for got in listener.got.values()) >= count, 5.0)
        time.sleep(SETTLE_S)  # anything beyond what the histories kept would show up now
    finally:
        if talker is not None:
            rt.remove(talker)
        if spun:
            rt.remove(listener)
        else:
            listener.destroy_node()
    return listener
