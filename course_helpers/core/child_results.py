"""Run a child-process procedure that measures something and reports one ``result``."""

from __future__ import annotations

from course_helpers.core.waiting import poll_until

EXIT_GRACE_S = 5.0  # s; a procedure ends by itself right after it reported


def run_child_for_result(rt, label: str, target, params: dict | None = None, env: dict | None = None,
                         timeout: float = 30.0) -> dict:
    """Run ``target`` (a top-level function that ends with ``report('result', ...)``) in a child.

    Args:
        rt: the kernel's runtime.
        label: the child's label (a child with that label is stopped first).
        target: the procedure, or ``'module:function'``.
        params: its keyword arguments (JSON values).
        env: environment changes for the child.
        timeout: seconds to wait for the result.

    Returns the data of the child's ``result`` report. Raises ``CourseError`` with the child's
    output if it ends without one, ``WaitTimeout`` if none came within ``timeout``.
    """
    child = rt.spawn(label, target, params=params or {}, env=env)
    try:
        result = child.wait_for_report("result", timeout, f"the result of {label}")
        poll_until(lambda: not child.alive, EXIT_GRACE_S)  # its participant leaves before the next one
        return result
    finally:
        rt.stop_child(label)
