"""Longest files first: how ``make test`` deals test files and notebooks out to parallel workers.

``--dist loadfile`` gives each pytest-xdist worker whole files (a notebook's cells must share one
kernel), and with ``--no-loadscope-reorder`` it hands them out in collection order, the next file
to whichever worker is nearly done. This hook orders the files by the seconds they took in a
measured run (``tests/durations.json``), longest first, so that a long file starts at once instead
of being dealt last to a worker that is already busy. A file missing from the record counts as the
median. ``pytest --record-durations ...`` measures a run and writes its files' seconds into the
record (``make durations`` does both stages).

Where every test must run (``.ci/run`` as root with apt sets ``COURSE_REQUIRE_ALL_TESTS=1``), a
skip is reported as a failure with its reason, so a missing browser or proxy cannot pass unseen.
"""

from __future__ import annotations

import json
import os
import signal
import statistics
from collections import defaultdict
from pathlib import Path

import pytest

RECORD = Path(__file__).parent / "tests" / "durations.json"

# A shell starts a background job (`make test &`, a CI step run with `&`) with SIGINT ignored; Python then
# installs no KeyboardInterrupt handler, and every process started from it inherits the ignoring. The tests
# that press Ctrl+C (on this process, or on a child such as a checker's student package) need what a
# terminal gives, so it is restored here, once per test process; children then start with the default.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
REQUIRE_ALL_ENV = "COURSE_REQUIRE_ALL_TESTS"


def pytest_addoption(parser):
    parser.addoption("--record-durations", action="store_true",
                     help="write each file's measured seconds into tests/durations.json")


def _file_of(nodeid: str) -> str:
    return nodeid.split("::", 1)[0]


def read_record() -> dict[str, float]:
    try:
        return {str(k): float(v) for k, v in json.loads(RECORD.read_text()).items()}
    except (OSError, ValueError) as exc:
        if RECORD.exists():
            raise pytest.UsageError(f"{RECORD} is not a JSON object of file -> seconds: {exc}") from exc
        return {}


@pytest.hookimpl(trylast=True)  # after the notebooks' conftest has added the second runs
def pytest_collection_modifyitems(session, config, items):
    record = read_record()
    files = list(dict.fromkeys(_file_of(item.nodeid) for item in items))
    known = [record[f] for f in files if f in record]
    default = statistics.median(known) if known else 0.0
    cost = {f: record.get(f, default) for f in files}
    rank = {f: i for i, f in enumerate(sorted(files, key=lambda f: -cost[f]))}  # ties keep their order
    items.sort(key=lambda item: rank[_file_of(item.nodeid)])  # stable: a file's items keep their order


class _Recorder:
    def __init__(self):
        self.seconds = defaultdict(float)

    def pytest_runtest_logreport(self, report):
        self.seconds[_file_of(report.nodeid)] += report.duration

    def pytest_sessionfinish(self, session):
        if not self.seconds:
            return
        record = read_record()
        record.update({f: round(s, 1) for f, s in self.seconds.items()})
        RECORD.write_text(json.dumps(dict(sorted(record.items())), indent=1) + "\n")
        print(f"\nrecorded the seconds of {len(self.seconds)} file(s) in {RECORD}")


def pytest_configure(config):
    # on the controller (or a run without workers): the workers' reports all arrive there
    if config.getoption("record_durations") and not hasattr(config, "workerinput"):
        config.pluginmanager.register(_Recorder(), "course-durations-recorder")


def _skip_is_a_failure(report) -> None:
    """With ``COURSE_REQUIRE_ALL_TESTS=1``, turn a skip (not an expected failure) into a failure."""
    if os.environ.get(REQUIRE_ALL_ENV) != "1" or not report.skipped or hasattr(report, "wasxfail"):
        return
    reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
    report.outcome = "failed"
    report.longrepr = f"skipped where every test must run ({REQUIRE_ALL_ENV}=1): {reason}"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    _skip_is_a_failure(outcome.get_result())


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    outcome = yield
    _skip_is_a_failure(outcome.get_result())
