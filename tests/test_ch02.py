"""The managed node (chapter 04, where services are known) and chapter 02's C++ program on rcl.

The lifecycle classes and the C++ source live in the notebooks' cells (that is where students read
and change them); these tests take them from there and run them for real: rclpy's lifecycle
services over Fast DDS, and a program compiled with this machine's C++ compiler against the venv's
rcl, run as a course child process and heard by a Python subscriber.
"""

from __future__ import annotations

import ast
import gc
import json
import os
import signal
import time

import pytest
from rclpy.node import Node
from std_msgs.msg import String

from course_helpers import CourseError
from course_helpers.chapters.ch02_executors import build_rcl_program, run_program
from course_helpers.chapters.ch02_executors.rcl_programs import NO_COMPILER, RclProgram

from .conftest import REPO

CHAPTER_02 = os.path.join(REPO, "notebooks", "02_nodes_and_executors.ipynb")  # the C++ appendix
CHAPTER_04 = os.path.join(REPO, "notebooks", "04_services.ipynb")  # the managed node


def cell_source(cell_id: str, notebook: str = CHAPTER_02) -> str:
    """The source of the code cell ``cell_id`` of ``notebook``."""
    with open(notebook, encoding="utf-8") as handle:
        cells = json.load(handle)["cells"]
    found = [c for c in cells if c.get("id") == cell_id]
    assert found, f"no cell {cell_id!r} in {notebook}"
    return "".join(found[0]["source"])


def notebook_classes(*cell_ids: str, notebook: str = CHAPTER_04) -> dict:
    """Run the notebook's class cells (definitions only) and return what they define."""
    namespace = {"Node": Node, "time": time}
    for cell_id in cell_ids:
        exec(compile(cell_source(cell_id, notebook), f"<notebook cell {cell_id}>", "exec"), namespace)  # noqa: S102
    return namespace


def rcl_talker_source() -> str:
    """The C++ text of the notebook's ``RCL_TALKER = r'''...'''`` cell."""
    tree = ast.parse(cell_source("cpp-source"))
    (assign,) = [n for n in tree.body if isinstance(n, ast.Assign) and n.targets[0].id == "RCL_TALKER"]
    return ast.literal_eval(assign.value)


# ---------------------------------------------------------------------- the managed node
@pytest.fixture
def managed(rt):
    """The notebook's ManagedTalker, NumberListener and LifecycleClient, spun in the kernel."""
    classes = notebook_classes("lifecycle-node", "lifecycle-client")
    talker = rt.add(classes["ManagedTalker"], console=False)
    listener = rt.add(classes["NumberListener"], console=False)
    client = rt.add(classes["LifecycleClient"], "/managed_talker", console=False)
    assert client.change_state.wait_for_service(5) and client.get_state.wait_for_service(5)

    def change(transition: str) -> bool:
        return rt.wait_for_future(client.request(transition), 5, transition).success

    def state() -> str:
        return rt.wait_for_future(client.state(), 5, "get_state").current_state.label

    return classes, talker, listener, change, state


def test_the_managed_talker_publishes_only_while_active(rt, managed):
    _classes, talker, listener, change, state = managed
    assert state() == "unconfigured" and talker.timer is None
    assert change("configure") and state() == "inactive"
    rt.wait_until(lambda: talker.publisher.get_subscription_count() > 0, 5, "the listener to match")
    start = talker.ticks
    rt.wait_until(lambda: talker.ticks >= start + 4, 3, "ticks while inactive")
    inactive = set(range(start + 1, talker.ticks + 1))
    assert change("activate") and state() == "active"
    start = talker.ticks
    rt.wait_until(lambda: talker.ticks >= start + 4, 3, "ticks while active")
    active = set(range(start + 1, start + 5))
    rt.wait_until(lambda: active <= listener.numbers, 5, "every tick of the active state")
    assert change("deactivate") and state() == "inactive"
    start = talker.ticks
    rt.wait_until(lambda: talker.ticks >= start + 4, 3, "ticks while inactive again")
    again = set(range(start + 1, start + 5))
    # A sentinel, not a window: active again, the talker's next number reaches the listener after
    # anything the same writer sent before it (reliable, in order), so a number published by mistake
    # while inactive would be there by then.
    assert change("activate")
    rt.wait_until(lambda: max(listener.numbers) > max(again), 5, "a number sent after the inactive spells")
    assert not listener.numbers & (inactive | again), sorted(listener.numbers)
    assert change("deactivate")
    assert change("cleanup") and state() == "unconfigured" and talker.timer is None
    assert change("shutdown") and state() == "finalized"


def test_a_transition_that_is_not_available_is_refused(managed):
    _classes, _talker, _listener, change, state = managed
    assert not change("activate")  # unconfigured: configure first
    assert state() == "unconfigured"


def test_a_failing_callback_keeps_the_old_state(rt, managed):
    classes, _talker, _listener, _change, _state = managed
    from rclpy.lifecycle import TransitionCallbackReturn

    class RefusingTalker(classes["ManagedTalker"]):
        def on_configure(self, state):
            return TransitionCallbackReturn.FAILURE  # e.g. a device that does not answer

    refusing = rt.add(RefusingTalker, console=False)  # replaces /managed_talker
    client = rt.add(classes["LifecycleClient"], "/managed_talker", console=False)
    assert client.change_state.wait_for_service(5)
    assert not rt.wait_for_future(client.request("configure"), 5, "configure").success
    assert rt.wait_for_future(client.state(), 5, "get_state").current_state.label == "unconfigured"
    assert refusing.timer is None


def test_shutting_down_an_active_talker_releases_its_timer(rt, managed):
    _classes, talker, _listener, change, state = managed
    assert change("configure") and change("activate")
    rt.wait_until(lambda: talker.ticks >= 2, 3, "ticks while active")
    assert change("shutdown") and state() == "finalized"
    assert talker.timer is None and talker.publisher is None
    assert not list(talker.timers), "a timer left on the node would keep calling tick"  # none can tick


def test_a_removed_managed_node_leaves_the_graph_at_once(rt, managed):
    """rclpy's LifecycleNode.destroy_node() leaves its state machine holding the rcl node; the
    runtime destroys that too, so a re-run cell does not list the old node beside the new one."""
    _classes, talker, _listener, _change, _state = managed
    gc.disable()  # the old node object stays alive: only the runtime's clean-up can remove it
    try:
        assert rt.remove(talker)
        rt.wait_until(lambda: "/managed_talker" not in rt.graph_nodes(), 2, "/managed_talker to leave")
    finally:
        gc.enable()


# ---------------------------------------------------------------------- C++ on rcl
@pytest.fixture(scope="module")
def talker_program() -> RclProgram:
    program = build_rcl_program("rcl_talker", rcl_talker_source())
    if program is None:
        pytest.skip(NO_COMPILER)
    return program


def test_the_rcl_talker_is_heard_by_python_and_stops_cleanly(rt, talker_program):
    heard: list[str] = []
    listener = rt.add(Node, "py_listener", console=False)
    listener.create_subscription(String, "cpp_chatter", lambda msg: heard.append(msg.data), 10)
    # heard in the kernel's own domain (not 0): the program took ROS_DOMAIN_ID from its environment
    assert rt.domain.domain_id != 0
    child = run_program("cpp_talker", talker_program, "--ros-args", "-r", "chatter:=cpp_chatter")
    try:
        rt.wait_for_child_node(child, "/cpp_talker", 10)
        rt.wait_until(lambda: len(heard) >= 5, 5, "five messages from the C++ talker")
        numbers = [int(text.rsplit("#", 1)[1]) for text in heard]
        assert numbers == list(range(numbers[0], numbers[0] + len(numbers)))  # reliable: none lost
        assert heard[0].startswith("hello from C++ #")
        topics = rt.graph.get_publisher_names_and_types_by_node("cpp_talker", "/")
        assert topics == [("/cpp_chatter", ["std_msgs/msg/String"])]  # remapped by rcl; nothing else
        assert rt.graph.get_service_names_and_types_by_node("cpp_talker", "/") == []
    finally:
        code = child.stop()
    assert code == 0, child.output_tail()
    assert "stopped cleanly" in child.log()
    rt.wait_until(lambda: "/cpp_talker" not in rt.graph_nodes(), 5, "/cpp_talker to leave the graph")


def test_the_rcl_talker_stops_cleanly_on_ctrl_c_too(rt, talker_program):
    child = run_program("cpp_talker", talker_program)
    rt.wait_for_child_node(child, "/cpp_talker", 10)
    os.killpg(child.leader_pid, signal.SIGINT)  # what Ctrl+C in a terminal does: the whole group
    assert child.wait_for_exit(5, "the program to stop on SIGINT") == 0, child.output_tail()


def test_a_compile_error_is_reported_with_the_compilers_words(rt):
    broken = rcl_talker_source().replace("rcl_publish(&publisher", "rcl_publsh(&publisher")
    with pytest.raises(CourseError, match=r"(?s)rcl_talker\.cpp did not compile.*rcl_publsh"):
        build_rcl_program("rcl_talker", broken)


def test_without_a_compiler_the_build_says_so_in_one_line(rt, monkeypatch, capsys):
    monkeypatch.setenv("CXX", "no-such-c++-compiler")
    assert build_rcl_program("rcl_talker", rcl_talker_source()) is None
    printed = capsys.readouterr().out.strip()
    assert printed == NO_COMPILER and "\n" not in printed
    assert "apt-get install g++" in printed


@pytest.mark.parametrize(("name", "source", "messages", "what"), [
    ("rcl-talker", "int main() {}", ("std_msgs",), "C identifier"),
    ("talker", "int x;", ("std_msgs",), "main"),
    ("talker", "int main() {}", ("no_such_msgs",), "no C type support"),
])
def test_bad_input_is_refused_before_compiling(name, source, messages, what):
    with pytest.raises(CourseError, match=what):
        build_rcl_program(name, source, messages)
