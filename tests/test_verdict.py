"""The one verdict (core/verdict.py) and the load meter it judges by (core/machine_load.py).

A busy machine is made with real CPU-bound processes outside the test's process tree
(:mod:`tools.busy_loops`), as a browser or another student's kernel would be.
"""

from __future__ import annotations

import gc
import subprocess
import sys
import time

import psutil
import pytest

from course_helpers.core.machine_load import LoadMeter, MachineLoad
from course_helpers.core.verdict import (
    ATTEMPTS,
    FAIL,
    INCONCLUSIVE,
    PASS,
    Verdict,
    VerdictError,
    claim,
    judge,
    judge_timing,
)
from tools.busy_loops import busy_loops

QUIET = MachineLoad(cores=2, seconds=2.0, others_cores=0.1, load_per_core=1.5, starved_share=0.03)
LOADED = MachineLoad(cores=2, seconds=2.0, others_cores=1.6, load_per_core=2.1, starved_share=0.4,
                     kernels=(11, 12), children=(13,))


def test_the_load_reading_decides_busy_not_the_load_average():
    assert not QUIET.busy  # a long 1-minute run queue is history, not this window
    assert MachineLoad(cores=2, seconds=1.0, others_cores=0.6, load_per_core=0.1).busy
    assert MachineLoad(cores=2, seconds=1.0, others_cores=0.0, load_per_core=0.1, starved_share=0.3).busy
    assert QUIET.describe().startswith("The machine was quiet")
    text = LOADED.describe()
    assert "1.6 of 2 cores" in text and "40%" in text and "2 other course kernels" in text
    assert "rt.shutdown_other_kernels()" in text
    one = MachineLoad(cores=2, seconds=1.0, others_cores=0.9, load_per_core=0.5, kernels=(11,))
    assert "1 other course kernel is running" in one.describe()  # not "are"


def test_the_meter_counts_busy_neighbours_as_others_and_its_own_children_as_its_own():
    with busy_loops(2):
        meter = LoadMeter()
        time.sleep(1.0)  # the window a measurement would take: the meter reads what happened in it
        loaded = meter.finish()
    assert loaded.busy and loaded.others_cores >= 0.5, loaded
    own = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        meter = LoadMeter()
        time.sleep(1.0)
        cpu_before = psutil.Process(own.pid).cpu_times()
        reading = meter.finish()
    finally:
        own.kill()
        own.wait()
    child_cores = (cpu_before.user + cpu_before.system) / reading.seconds
    assert child_cores > 0.05, child_cores  # it got some CPU, however busy the machine
    assert reading.own_cores >= 0.9 * child_cores, (reading, child_cores)  # counted as this tree's


def test_a_verdict_by_construction_ignores_the_load():
    assert judge("every sample arrived", True, "60 of 60").line() == "\u2714 every sample arrived: 60 of 60"
    failed = judge("every sample arrived", False, "57 of 60")
    assert failed.outcome == FAIL and failed.line().startswith("\u2718 every sample arrived")
    with pytest.raises(VerdictError, match="57 of 60"):
        failed.raise_unless_passed()
    with pytest.raises(AssertionError):  # nbval and pytest see an assertion
        claim("every sample arrived", False, "57 of 60")
    assert claim("every sample arrived", True, "60 of 60").passed


@pytest.mark.makes_load  # busy loops in the timing stage would spoil the measurements beside them
def test_a_timing_verdict_passes_when_the_bound_holds_whatever_the_load():
    with busy_loops(2):
        verdict, value = judge_timing("the answer comes within 1 s", lambda: 0.01, lambda s: s < 1.0,
                                      show=lambda s: f"{s:.2f} s")
    assert verdict.outcome == PASS and verdict.attempts == 1 and value == 0.01
    assert verdict.line() == "\u2714 the answer comes within 1 s: 0.01 s"


@pytest.mark.timing  # it calls judge_timing, though the bound is never near
def test_no_garbage_collection_runs_inside_a_timing_measurement_and_the_collector_comes_back():
    collections = []  # (generation, while measuring) of every collection that ran
    measuring = [False]

    def note(phase, info):
        if phase == "start":
            collections.append((info["generation"], measuring[0]))

    def allocating_cycles():  # enough new containers to start collections many times over
        measuring[0] = True
        try:
            for _ in range(20_000):
                cycle = []
                cycle.append(cycle)
        finally:
            measuring[0] = False
        return 0.01

    gc.callbacks.append(note)
    try:
        judge_timing("it takes under 1 s", allocating_cycles, lambda s: s < 1.0)
        assert gc.isenabled()
        allocating_cycles_after = [[] for _ in range(5_000)]  # the collector runs again afterwards
        with pytest.raises(RuntimeError):
            judge_timing("it takes under 1 s", _raises, lambda s: s < 1.0)
        assert gc.isenabled()
        gc.disable()  # a user who turned the collector off keeps it off
        judge_timing("it takes under 1 s", lambda: 0.01, lambda s: s < 1.0)
        assert not gc.isenabled()
    finally:
        gc.enable()
        gc.callbacks.remove(note)
    assert not [gen for gen, inside in collections if inside], collections
    assert collections and allocating_cycles_after  # the collector ran outside the measurement


def _raises():
    raise RuntimeError("the measurement broke")


@pytest.mark.makes_load
def test_a_missed_bound_on_a_busy_machine_is_inconclusive_after_its_retries_and_says_why():
    measurements = []

    def measure() -> float:
        time.sleep(0.3)  # the measured work: the busy loops share the machine meanwhile
        measurements.append(2.0)
        return 2.0

    with busy_loops(2):
        verdict, _ = judge_timing("the answer comes within 1 s", measure, lambda s: s < 1.0,
                                  show=lambda s: f"{s:.1f} s")
    assert verdict.outcome == INCONCLUSIVE and len(measurements) == verdict.attempts == ATTEMPTS
    line = verdict.line()
    assert "\n" not in line
    assert line.startswith("inconclusive (busy machine): the answer comes within 1 s: 2.0 s")
    assert "too busy to judge it" in line and "cores" in line and f"measured {ATTEMPTS} times" in line
    assert "run it again" in line  # what to do
    with pytest.raises(VerdictError) as raised:  # never a pass
        verdict.raise_unless_passed()
    assert raised.value._render_traceback_() == [f"\x1b[0;31m{line}\x1b[0m"]  # one line in a notebook


def test_a_fail_names_the_measurement_and_an_inconclusive_the_load():
    failed = Verdict("seen within 0.5 s", FAIL, "p90 3.1 s", QUIET, 1)
    assert failed.line() == "\u2718 seen within 0.5 s: p90 3.1 s" and failed.why() == ""
    unsure = Verdict("seen within 0.5 s", INCONCLUSIVE, "p90 3.1 s", LOADED, 3)
    assert "2 other course kernels and 1 child process of other course kernels running" in unsure.why()
    with pytest.raises(ValueError, match="attempts"):
        judge_timing("x", lambda: 0, lambda v: True, attempts=0)
