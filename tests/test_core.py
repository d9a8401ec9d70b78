"""The core layer's small guarantees: the node hook, the process layer and its channel, waiting."""

from __future__ import annotations

import os
import threading

import pytest
from rclpy.exceptions import NotInitializedException
from rclpy.node import Node

from course_helpers import CourseError, WaitTimeout
from course_helpers.core import processes
from course_helpers.core.node_hook import hook_installed
from course_helpers.core.waiting import poll_until, wait_until
from course_helpers.nodes import Talker, make_talker

from .helpers_children import count_then_report, fail_after_report


class BrokenAfterInit(Node):
    """A student's constructor that fails after ``super().__init__``."""

    def __init__(self):
        super().__init__("half_built")
        raise ValueError("typo in my constructor")


class Outer(Node):
    """Builds another node inside its own constructor (a nested build)."""

    def __init__(self):
        super().__init__("outer")
        self.inner = Node("inner")


def test_the_node_hook_is_restored_after_use_and_after_an_error(rt):
    assert not hook_installed()
    rt.add(Talker, console=False)
    assert not hook_installed()
    with pytest.raises(ValueError, match="typo"):
        rt.add(BrokenAfterInit)
    assert not hook_installed()
    with pytest.raises(NotInitializedException):  # rclpy's own default context again, not the runtime's
        Node("plain_after_hook")
    assert "/half_built" not in rt.nodes()


def test_a_half_built_node_leaves_nothing_in_the_graph(rt):
    with pytest.raises(ValueError):
        rt.add(BrokenAfterInit)
    # this process's own graph cache drops a destroyed node at once (no window to wait out)
    assert "/half_built" not in rt.graph_nodes()


def test_the_hook_is_reentrant_and_uses_the_innermost_context(rt):
    outer = rt.build(Outer)
    try:
        assert outer.context is rt.context and outer.inner.context is rt.context
    finally:
        outer.inner.destroy_node()
        outer.destroy_node()
    assert not hook_installed()


def test_nodes_built_in_other_threads_keep_their_own_context(rt):
    seen = {}
    release = threading.Event()

    def slow_factory():
        release.wait(5)
        return Node("slow_factory_node")

    worker = threading.Thread(target=lambda: seen.setdefault("node", rt.build(slow_factory)))
    worker.start()
    try:
        rt.wait_until(hook_installed, 5, "the worker's build to start")
        with pytest.raises(NotInitializedException):  # this thread's Node() is not redirected
            Node("other_thread_node")
    finally:
        release.set()
        worker.join(10)
    assert seen["node"].context is rt.context
    seen["node"].destroy_node()


def test_call_in_executor_from_a_callback_runs_directly(rt):
    results = []
    node = rt.node("caller_in_executor", console=False)
    node.create_timer(0.01, lambda: results.append(rt.call_in_executor(lambda: "ran", timeout=1.0))
                      if not results else None)
    rt.wait_until(lambda: results, 3, "the timer's call")
    assert results == ["ran"]


def test_restart_with_a_bad_executor_stops_nothing(rt):
    talker = rt.add(Talker, console=False)
    with pytest.raises(CourseError, match="executor must be 'single' or 'multi'"):
        rt.restart("bad")
    assert rt.running and rt.get("/talker") is talker


def test_spawn_takes_the_function_itself_and_reports_ready(rt):
    child = rt.spawn("fn_talker", make_talker, params={"name": "fn_talker"}, wait_for="/fn_talker")
    assert child.last("ready") == {"nodes": ["/fn_talker"], "pid": child.pid}
    assert rt.stop_child("fn_talker") == 0


def test_spawn_takes_a_node_subclass(rt):
    rt.spawn("class_talker", Talker, params={"name": "class_talker"}, wait_for="/class_talker")
    assert rt.stop_child("class_talker") == 0


@pytest.mark.parametrize("target, words", [
    (lambda: None, "not a lambda"),
    ("no_colon_here", "'package.module:callable'"),
    (42, "must be a function"),
])
def test_a_target_a_child_cannot_import_is_refused_before_anything_starts(rt, target, words):
    with pytest.raises(CourseError, match=words):
        rt.spawn("bad_target", target)
    assert "bad_target" not in rt.children()


def test_a_procedure_reports_over_the_channel_and_exits(rt):
    child = rt.spawn("counter", count_then_report, params={"count": 3})
    assert child.wait_for_report("done", 20) == {"total": 3}
    assert [r["i"] for r in child.reports("step")] == [0, 1, 2]
    assert child.wait_for_exit(10) == 0
    assert "step" not in child.log()  # reports never go through the log


def test_a_failing_procedure_names_its_error(rt):
    child = rt.spawn("failing", fail_after_report)
    assert child.wait_for_exit(20) == 1
    assert child.last("error") == {"type": "RuntimeError", "message": "measured nothing"}
    with pytest.raises(CourseError, match="exited with code 1 before its 'never' report"):
        child.wait_for_report("never", 5)


def test_processes_started_together_stop_together(rt):
    for name in ("t1", "t2", "t3"):
        rt.spawn(name, make_talker, params={"name": name}, wait_for=f"/{name}")
    codes = rt.stop_children(["t1", "t2", "t3"])
    assert codes == {"t1": 0, "t2": 0, "t3": 0}
    assert not rt.children()


def test_program_processes_die_with_the_layer_and_run_reports_a_timeout(tmp_path):
    child = processes.start("sleeper", processes.program_argv("sleep", "30"), group="test", channel=False)
    assert child.alive
    assert processes.stop(["sleeper"], group="test")["sleeper"] is not None
    code, output = processes.run(["sh", "-c", "echo one; echo two"])
    assert (code, output) == (0, "one\ntwo")
    with pytest.raises(CourseError, match="took longer than 0.5 s"):
        processes.run(["sleep", "5"], timeout=0.5)


def test_run_works_in_a_process_that_is_itself_a_course_child(monkeypatch):
    """A graded kernel (and any child of the process layer) carries the PID of the process that started
    it in COURSE_PARENT_PID: a command that run() starts must still run, not take that PID for its own
    parent's, find it gone, and exit 0 without doing anything (a colcon build that built nothing)."""
    monkeypatch.setenv(processes.PARENT_ENV, str(os.getppid()))
    assert processes.run(["sh", "-c", "echo built"]) == (0, "built")


def test_waiting_names_what_it_waited_for():
    assert poll_until(lambda: False, 0.05) is False
    with pytest.raises(WaitTimeout, match="waiting for the moon"):
        wait_until(lambda: False, 0.05, "the moon")


@pytest.mark.parametrize("name", ["/odom//filtered", "odom//filtered", "2fast", "/bad name"])
def test_invalid_topic_names_are_named(name):
    from course_helpers.core.validation import check_topic_name

    with pytest.raises(CourseError, match=f"invalid topic name {name!r}"):
        check_topic_name(name)


ORPHAN_LAUNCHER = """
import os, pathlib, signal, subprocess, sys, time
signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})  # so the kernel-death signal is lost
env = dict(os.environ, COURSE_PARENT_PID=str(os.getpid()))
out = pathlib.Path(sys.argv[1])
child = subprocess.Popen([sys.executable, '-m', 'course_helpers.core.child', 'run',
                          'course_helpers.nodes.chatter:Talker', '{}'], env=env,
                         stdout=out.open('w'), stderr=subprocess.DEVNULL)
print(child.pid, flush=True)
while ' ready: ' not in out.read_text():  # the child has built its talker and serves it
    time.sleep(0.05)
print('served', flush=True)
os._exit(0)  # the "kernel" vanishes without a clean-up
"""


def test_a_child_whose_kernel_vanished_exits_even_if_the_death_signal_is_lost(tmp_path):
    import subprocess
    import sys

    import psutil

    launcher = [sys.executable, "-c", ORPHAN_LAUNCHER, str(tmp_path / "child.out")]
    out = subprocess.run(launcher, capture_output=True, text=True, timeout=60).stdout
    pid = int(out.split()[0])
    assert out.split()[1:] == ["served"], out  # the child was serving when its kernel vanished

    def gone() -> bool:
        try:
            return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
        except psutil.NoSuchProcess:
            return True

    # the watchdog notices within half a second; the clean-up takes a moment more
    wait_until(gone, 15, f"the orphaned child {pid} to exit")
