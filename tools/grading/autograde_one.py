"""Autograde one student's submission with nbgrader: ``autograde_one.py COURSE_DIR ASSIGNMENT STUDENT``.

Run by ``tools/assignments.py grade`` as a process of its own for every submission, with the
student's own environment (:mod:`tools.grading.isolation`) and a wall clock. It becomes a child
subreaper first, so every process the student's kernel leaves behind - even one that
detached itself - stays its descendant and can be found. It then runs nbgrader's autograde
with the course's ``nbgrader_config.py`` and :class:`grading.guarded.GuardedExecute` in place
of nbgrader's Execute. Exit status 0 when nbgrader succeeded.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

from tools.grading.isolation import become_subreaper, sweep_descendants


def grading_config(course_dir: str, timeout: int | None = None, record: str = ""):
    """The course's nbgrader config with the guarded executor in the autograde pipeline."""
    from nbgrader.preprocessors import Execute
    from traitlets.config.loader import PyFileConfigLoader

    from tools.grading.guarded import GuardedExecute
    from tools.kernels import AsyncPrivateSocketKernelManager

    config = PyFileConfigLoader("nbgrader_config.py", path=course_dir).load_config()
    config.CourseDirectory.root = course_dir
    from nbgrader.converters import Autograde

    steps = list(config.Autograde.autograde_preprocessors) if "autograde_preprocessors" in config.Autograde \
        else list(Autograde.class_traits()["autograde_preprocessors"].default())
    config.Autograde.autograde_preprocessors = [GuardedExecute if s is Execute else s for s in steps]
    if timeout:
        config.Execute.timeout = timeout
    limit = (config.Execute.timeout if "timeout" in config.Execute
             else Execute.class_traits()["timeout"].default())
    message = f"the cell ran longer than {limit} s and was interrupted"
    config.Execute.error_on_timeout = {"ename": "CellTimeoutError", "evalue": message,
                                       "traceback": [f"CellTimeoutError: {message}"]}
    config.GuardedExecute.record_path = record
    # Several submissions may be graded at once (the tests do): over TCP two kernels could be handed
    # one port, and one would die before its first cell (tools/kernels.py).
    config.Execute.kernel_manager_class = AsyncPrivateSocketKernelManager
    return config


def _sweep_into_record(record: str) -> None:
    """Kill what the student's kernel left running (this process is their subreaper, so a detached
    process is its child now) and add what was killed to the run record as ``killed_after_run``.

    Done here, before this process exits: the course's supervisor above it would otherwise end
    those processes without a word, and the grade's notes would not say that anything was left.
    """
    left = sweep_descendants()
    if not record:
        return
    try:
        with open(record, encoding="utf-8") as handle:
            data = json.load(handle)
    except (OSError, ValueError):
        data = {}
    data["killed_after_run"] = left
    with open(record + ".new", "w", encoding="utf-8") as handle:
        json.dump(data, handle)
    os.replace(record + ".new", record)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("course_dir")
    parser.add_argument("assignment")
    parser.add_argument("student")
    parser.add_argument("--timeout", type=int, default=None, help="seconds per cell (Execute.timeout)")
    parser.add_argument("--record", default="", help="where GuardedExecute writes what happened (JSON)")
    args = parser.parse_args(argv)
    become_subreaper()
    from nbgrader.apps import NbGraderAPI

    course_dir = os.path.abspath(args.course_dir)
    os.chdir(course_dir)
    config = grading_config(course_dir, args.timeout, args.record)
    api = NbGraderAPI(config=config)
    result = api.autograde(args.assignment, args.student, force=True, create=True)
    _sweep_into_record(args.record)
    print(result.get("log", ""))
    if not result["success"]:
        print(result.get("error", ""), file=sys.stderr)
    return 0 if result["success"] else 1


if __name__ == "__main__":
    sys.exit(main())
