"""Strict nbval of the course, then "Run All" a second time in the same kernel.

``pytest --nbval notebooks/`` runs every code cell and compares its outputs with the committed
ones (the first pass). This file adds a second pass to each notebook: every cell again, in the same
kernel, checked only for errors, then a last item that asserts the second run left no duplicate
nodes and one executor thread. So each notebook runs exactly twice, and re-running a notebook
(what students do all the time) is tested where the notebook is tested. Set
``COURSE_NBVAL_RERUN=0`` to run the first pass only. ``--dist loadfile`` keeps a notebook on one
worker (the cells also carry an xdist_group mark, which pytest 9 no longer lets pytest-xdist use).

A failed cell's report ends with what the cell wrote to stderr, when it wrote anything: nbval itself
only says that an unexpected stderr field appeared, not what was in it.

Cells that need an optional part of the machine start with a line ``# COURSE_NEEDS: <part>``
(``ros1``: ROS 1's rospy and rosmaster for the system Python; ``netns``: private network
namespaces; ``cyclonedds``: Eclipse Cyclone DDS's Python binding; ``tshark``: Wireshark's
``tshark`` and ``dumpcap``). A cell may name several parts, one line each. Where a part is missing,
those cells (and only those) are skipped, with the one-line reason the course gives, which names the
install (``pytest -rs`` lists it). In a notebook they print that line.

A cell whose work is a build names its builder in its metadata, ``"course_builds": "<builder>"``
(``rosidl``, ``colcon`` or ``rcl_program``). The builder stops itself, with an error that says which
step took too long, after its own limit; so such a cell gets that limit on top of the usual cell
timeout, for nbval and for pytest-timeout alike. A loaded machine makes a build longer, never wrong,
and the cell timeout is not a second, tighter judge of its speed: a fresh-clone CI run had chapter
09's rosidl build (12 s idle) stopped by the 120 s cell timeout.
"""

from __future__ import annotations

import os
import re

import nbformat
import pytest

NEEDS_MARK = re.compile(r"^# COURSE_NEEDS: (\w+)\s*$", re.MULTILINE)


def _kernels_on_private_sockets() -> None:
    """nbval's workers start their kernels at the same moment; over TCP two of them can be handed the
    same port and one kernel dies before its first cell (tools/kernels.py). nbval builds its
    KernelManager by the name in its module, so that name gets the one with sockets of its own."""
    import nbval.kernel

    from tools.kernels import PrivateSocketKernelManager

    nbval.kernel.KernelManager = PrivateSocketKernelManager


_kernels_on_private_sockets()


def _reason_ros1() -> str | None:
    from course_helpers.chapters.ch01_ros1.ros1 import ros1_unavailable_reason

    return ros1_unavailable_reason()


def _reason_netns() -> str | None:
    from course_helpers.core.netns import unavailable_reason

    return unavailable_reason()


def _reason_cyclonedds() -> str | None:
    from course_helpers.chapters.ch07_dds.cyclone import cyclone_unavailable_reason

    return cyclone_unavailable_reason()


def _reason_tshark() -> str | None:
    from course_helpers.core.rtps_capture import unavailable_reason

    return unavailable_reason()


NEEDS = {"ros1": _reason_ros1, "netns": _reason_netns, "cyclonedds": _reason_cyclonedds,
         "tshark": _reason_tshark}


def needs_of(source: str) -> list[str]:
    """The optional parts a cell's source says it needs (``# COURSE_NEEDS: ros1`` lines)."""
    return NEEDS_MARK.findall(source)


BUILD_KEY = "course_builds"


def build_limits_s() -> dict[str, float]:
    """How long each builder runs at most before it stops itself: ``course_builds`` value -> seconds."""
    from course_helpers.chapters.ch02_executors.rcl_programs import COMPILE_TIMEOUT_S
    from course_helpers.chapters.ch09_packages.colcon import COLCON_TIMEOUT_S
    from course_helpers.core.build_interfaces import BUILD_LIMIT_S

    return {"rosidl": BUILD_LIMIT_S, "colcon": COLCON_TIMEOUT_S, "rcl_program": COMPILE_TIMEOUT_S}


def _bound_builds(items, config) -> None:
    """Give each cell that builds its builder's limit on top of the usual cell timeout."""
    from nbval.plugin import IPyNbCell

    limits, usual = None, float(config.option.nbval_cell_timeout)
    for item in items:
        builder = item.cell.metadata.get(BUILD_KEY) if isinstance(item, IPyNbCell) else None
        if builder is None:
            continue
        limits = limits or build_limits_s()
        if builder not in limits:
            raise pytest.UsageError(f"{item.nodeid}: {BUILD_KEY} {builder!r} is not a known builder; "
                                    f"known: {sorted(limits)}")
        item.course_cell_timeout = usual + limits[builder]
        item.add_marker(pytest.mark.timeout(item.course_cell_timeout))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item):
    """nbval reads one cell timeout for all cells as each runs: a build cell's is set around its run."""
    bound = getattr(item, "course_cell_timeout", None)
    option = item.config.option
    usual = option.nbval_cell_timeout
    if bound is not None:
        option.nbval_cell_timeout = bound
    try:
        yield
    finally:
        option.nbval_cell_timeout = usual


def skip_reason(source: str, reasons: dict) -> str | None:
    """Why a cell must be skipped here (its first missing part), or None. ``reasons`` caches the probes."""
    for part in needs_of(source):
        if part not in NEEDS:
            raise pytest.UsageError(f"# COURSE_NEEDS: {part} is not a known part; known: {sorted(NEEDS)}")
        if part not in reasons:
            reasons[part] = NEEDS[part]()
        if reasons[part] is not None:
            return f"needs {part}: {reasons[part]}"
    return None


def _skip_missing_parts(items) -> None:
    from nbval.plugin import IPyNbCell

    reasons: dict = {}
    for item in items:
        if isinstance(item, IPyNbCell):
            reason = skip_reason(item.cell.source, reasons)
            if reason is not None:
                item.add_marker(pytest.mark.skip(reason=reason))

AFTER_RERUN = """
import collections, threading
from course_helpers import get_runtime
_rt = get_runtime()
_names = [ns.rstrip('/') + '/' + n for n, ns in _rt.graph.get_node_names_and_namespaces()]
_dupes = sorted(n for n, c in collections.Counter(_names).items() if c > 1)
_threads = sum(t.name == 'ros-executor' for t in threading.enumerate())
assert not _dupes and _threads == 1, (
    f'after running twice: duplicate nodes {_dupes}, {_threads} executor threads')
"""


def pytest_collection_modifyitems(session, config, items):
    if os.environ.get("COURSE_NBVAL_RERUN", "1") == "0":
        _skip_missing_parts(items)
        _bound_builds(items, config)
        return
    from nbval.plugin import IPyNbCell

    ordered, files = [], {}
    for item in items:
        if isinstance(item, IPyNbCell):
            files.setdefault(item.parent, []).append(item)
        else:
            ordered.append(item)
    for notebook, cells in files.items():
        ordered += cells
        for cell in cells:
            options = dict(cell.options)
            options["check"] = False  # the second run must not fail; its outputs were compared once
            ordered.append(IPyNbCell.from_parent(notebook, name=f"{cell.name} (run 2)",
                                                 cell_num=cell.cell_num, cell=cell.cell,
                                                 options=_defaulting(options)))
        check = nbformat.v4.new_code_cell(AFTER_RERUN)
        ordered.append(IPyNbCell.from_parent(notebook, name="after run 2: no duplicates",
                                             cell_num=len(cells), cell=check,
                                             options=_defaulting({"check": False})))
    for item in ordered:
        if isinstance(item, IPyNbCell):
            item.add_marker(pytest.mark.xdist_group(f"notebook-{item.parent.name}"))
    _skip_missing_parts(ordered)
    _bound_builds(ordered, config)
    items[:] = ordered


def _defaulting(options: dict):
    from collections import defaultdict

    return defaultdict(bool, options)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Add the stderr text of a failed cell to its report (nbval names only the unexpected field)."""
    outcome = yield
    report = outcome.get_result()
    outputs = getattr(item, "test_outputs", None) or []
    if report.when != "call" or not report.failed:
        return
    text = "".join(out.get("text", "") for out in outputs
                   if out.get("output_type") == "stream" and out.get("name") == "stderr")
    if text:
        report.sections.append(("what the cell wrote to stderr", text))
