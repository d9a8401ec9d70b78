"""Chapter 09 (packages and interfaces), with real colcon builds and processes."""

from __future__ import annotations

import re
import subprocess

import pytest

from course_helpers import CourseError
from course_helpers.chapters.ch09_packages import (
    MessagePublisher,
    Workspace,
    build_interface_package,
    create_interface_package,
    interface_env,
    kernel_prefix,
    load_interfaces,
    running_processes,
    stop_process,
)
from course_helpers.chapters.ch09_packages.progress import BuildSteps, short_line
from course_helpers.checks.ch09_packages import check_package
from course_helpers.nodes import Talker
from course_helpers.solutions.ch09_packages import reference_package

from .conftest import REPO

BUILD_DIRS = re.compile(r"(^|/)(build|install|log)(/|$)")


def _git_status() -> set[str]:
    out = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all"], cwd=REPO,
                         capture_output=True, text=True, check=True).stdout
    return {line[3:] for line in out.splitlines()}


def test_colcon_build_runs_in_a_temp_dir_and_leaves_nothing_in_the_repo(rt):
    before = _git_status()
    ws = Workspace("test_ws")
    try:
        source = reference_package()["robot_heartbeat/heartbeat.py"]
        ws.create_package("warehouse_tools", "heartbeat", dependencies=["rclpy", "std_msgs"],
                          node_source=source)
        build = ws.build()
        assert build.ok, build.log_tail()
        assert build.package_types == {"warehouse_tools": "ros.ament_python"}
        for folder in ("src", "build", "install", "log"):
            assert (ws.root / folder).is_dir()
        changes = ws.setup_changes()
        assert changes["AMENT_PREFIX_PATH"] == ["$WS/install/warehouse_tools"]
        assert changes["PYTHONPATH"] == ["$WS/install/warehouse_tools/lib/python3.X/site-packages"]
        assert ws.find_executable("warehouse_tools", "heartbeat").name == "heartbeat"
        with pytest.raises(CourseError, match="No executable 'nope'"):
            ws.find_executable("warehouse_tools", "nope")
        with pytest.raises(CourseError, match="not found"):
            ws.find_executable("no_such_package", "heartbeat")

        child = ws.run("warehouse_tools", "heartbeat", wait_for="/heartbeat")
        assert child.alive
        heard = rt.wait_for_messages("/heartbeat", "std_msgs/msg/String", count=2, timeout=5)
        assert heard[0].data == "robot_heartbeat alive"
        assert stop_process("heartbeat") == 0  # Ctrl+C: a clean exit
    finally:
        ws.cleanup()
    assert not ws.root.exists()
    assert "heartbeat" not in running_processes()
    created = _git_status() - before
    assert not [path for path in created if BUILD_DIRS.search(path)], created


def test_workspace_rerun_replaces_the_old_one(rt):
    first = Workspace("rerun_ws")
    second = Workspace("rerun_ws")
    try:
        assert not first.root.exists() and second.root.exists()
    finally:
        second.cleanup()


def test_package_checker_accepts_reference_and_rejects_wrong_ones(rt):
    report = check_package(reference_package())
    assert report.passed, report.summary()

    no_entry_point = reference_package()
    no_entry_point["setup.py"] = no_entry_point["setup.py"].replace(
        "'heartbeat = robot_heartbeat.heartbeat:main',", "")
    report = check_package(no_entry_point)
    assert not report.passed
    failed = [c for c in report.criteria if not c.passed]
    assert failed[0].name == "`ros2 run robot_heartbeat heartbeat` finds the executable"
    assert "console_scripts" in failed[0].hint

    bad_manifest = reference_package()
    bad_manifest["package.xml"] = bad_manifest["package.xml"].replace("student@example.com", "nobody")
    failed = {c.name for c in check_package(bad_manifest).criteria if not c.passed}
    assert failed == {"colcon identified an ament_python package"}

    # The notebook's own /heartbeat node would fake a pass: the checker refuses to run then.
    rt.add(Talker, name="heartbeat", topic="heartbeat", console=False)
    report = check_package(reference_package())
    assert not report.passed and "already in the graph" in report.criteria[-1].detail
    rt.remove("/heartbeat")

    missing_files = reference_package()
    del missing_files["resource/robot_heartbeat"]
    assert not check_package(missing_files).passed
    assert not check_package("not a dict").passed


def test_workspace_rejects_bad_names():
    ws = Workspace("names_ws")
    try:
        with pytest.raises(CourseError, match="REP 144"):
            ws.create_package("Bad-Name", "node")
        with pytest.raises(CourseError, match="relative"):
            ws.write_package("ok_name", {"/etc/passwd": ""})
        with pytest.raises(CourseError, match="leaves the package"):
            ws.write_package("ok_name", {"../../escape.py": ""})
        with pytest.raises(CourseError, match="CamelCase"):
            create_interface_package(ws.src, "my_msgs", messages={"lower": "int32 a"})
    finally:
        ws.cleanup()


@pytest.mark.slow
def test_new_message_is_built_loaded_and_used_across_processes(rt):
    ws = Workspace("msgs_ws")
    try:
        definition = "string bin_id\nfloat32 fill_ratio\nstring[] item_ids"
        source = create_interface_package(ws.src, "chapter09_test_msgs", messages={"BinLevel": definition})
        lines = []
        built = build_interface_package(source, ws.root / "install_msgs", progress=lines.append)
        assert built.rebuilt and lines[-1] == "done"
        module = load_interfaces(built)
        rt.spawn("bin_sensor", MessagePublisher,
                 params={"type_name": "chapter09_test_msgs/msg/BinLevel", "topic": "bins",
                         "fields": {"bin_id": "A3", "fill_ratio": 0.5, "item_ids": ["w-1", "w-2"]},
                         "name": "bin_sensor"},
                 env=interface_env(built), wait_for="/bin_sensor")
        got = rt.wait_for_messages("/bins", module.BinLevel, count=2, timeout=5)
        assert [m.bin_id for m in got] == ["A3", "A3"] and got[0].fill_ratio == 0.5
        assert list(got[0].item_ids) == ["w-1", "w-2"]  # the array field crossed the process boundary
        assert load_interfaces(built) is module  # loading again is a no-op
        # Running the notebook again: the same definitions in a new workspace are not built twice.
        again = create_interface_package(ws.root / "src_again", "chapter09_test_msgs",
                                         messages={"BinLevel": definition})
        lines.clear()
        second = build_interface_package(again, ws.root / "install_msgs", progress=lines.append)
        assert not second.rebuilt and "up to date" in lines[1] and lines[-1] == "done"
        assert second.seconds < built.seconds
    finally:
        rt.stop_child("bin_sensor")
        ws.cleanup()


def test_build_steps_record_what_each_step_took():
    steps = BuildSteps("rosidl")
    assert steps.text() == "rosidl: running"
    for line in ("configure ... (log: /tmp/ws_x/build_interfaces/pkg/build.log)", "build ...", "install ..."):
        steps.add(line)
    steps.add("done")
    lines = steps.text().splitlines()
    assert lines[0].startswith("rosidl: succeeded in ") and lines[0].endswith(" s")
    assert [line.split(" s  ", 1)[1] for line in lines[1:]] == [
        "configure ... (log: .../build.log)", "build ...", "install ..."]
    assert "<table>" in steps.html() and "#2e7d32" in steps.html()
    failed = BuildSteps("colcon build")
    failed.add("$ colcon build")
    failed.add("FAILED")
    assert failed.headline().startswith("colcon build: FAILED after")
    assert short_line("x" * 200).endswith("...") and len(short_line("x" * 200)) == 90


def test_kernel_prefix_lasts_for_the_process():
    first = kernel_prefix("warehouse_msgs")
    assert first == kernel_prefix("warehouse_msgs") and first.name == "install"
    assert first.parent.name == "warehouse_msgs" and first.parent.parent.is_dir()
    with pytest.raises(CourseError, match="REP 144"):
        kernel_prefix("Bad-Name")
