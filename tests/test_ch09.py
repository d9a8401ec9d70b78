"""Chapter 09 (packages and interfaces), with real colcon builds and processes."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

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
    read_package,
    running_processes,
    stop_process,
    write_package_files,
)
from course_helpers.chapters.ch09_packages.progress import BuildSteps, short_line
from course_helpers.chapters.ch09_packages.provisioned import dependency_closure, installed_ros_packages
from course_helpers.checks import ch09_packages as checker
from course_helpers.checks.ch09_packages import (
    CTRL_C_CRITERION,
    DEPENDS,
    EXECUTABLE,
    NODE,
    PACKAGE,
    SHUTDOWN_RACE,
    TOPIC,
    check_package,
)
from course_helpers.nodes import Talker
from course_helpers.solutions.ch09_packages import reference_package
from tools.grading import source as grading_source

from .conftest import REPO
from .criteria_registry import assert_reference_criteria, failing

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


# --------------------------------------------------------------------- checker: a wrong package per criterion
FILES_THERE = "the files of an ament_python package are there"
NAMED = f"package.xml names {PACKAGE} and declares the ament_python build type"
IDENTIFIED = "colcon identified an ament_python package"
FINDS = f"`ros2 run {PACKAGE} {EXECUTABLE}` finds the executable"
SHOWS_NODE = f"its process shows node {NODE} in the graph"
# the checker reports these only when they fail, so the reference's report does not name them
ONLY_WHEN_FAILED = {"the package is a dict of files", "package.xml is valid XML",
                    "the files can be written into src/"}
NOT_ALONE = f"no other {NODE} runs before the package starts"  # fails on the notebook's graph (test below)
STARTS = "the executable starts"  # see EXEMPT
MODULE = f"{PACKAGE}/heartbeat.py"


def _criterion(report, name: str):
    """The criterion ``name`` of ``report``; a report without it fails the test with the whole report."""
    found = [c for c in report.criteria if c.name == name]
    assert len(found) == 1, f"no criterion {name!r} in:\n{report.summary()}"
    return found[0]


def _failed(report) -> set[str]:
    return {c.name for c in report.criteria if not c.passed}


def _covered(table) -> set[str]:
    return set().union(*(param.values[1] for param in table))


def _changed(path: str, old: str, new: str):
    """A wrong package: the reference's files with ``old`` replaced by ``new`` in ``path``."""
    def make(files: dict) -> dict:
        assert old in files[path], (path, old)
        return {**files, path: files[path].replace(old, new)}
    return make


def _without(path: str):
    return lambda files: {name: text for name, text in files.items() if name != path}


NO_ENTRY_POINT = _changed("setup.py", f"'{EXECUTABLE} = {PACKAGE}.heartbeat:main',", "")
SCRIPTS_IN_BIN = _changed("setup.cfg", f"install_scripts=$base/lib/{PACKAGE}", "install_scripts=$base/bin")

PACKAGE_WRONG = [
    pytest.param(lambda files: list(files.items()), {"the package is a dict of files"}, id="list-of-pairs"),
    pytest.param(_without("setup.cfg"), {FILES_THERE}, id="no-setup-cfg"),
    pytest.param(_without(f"resource/{PACKAGE}"), {FILES_THERE}, id="no-marker"),
    pytest.param(_changed("package.xml", "</license>", "<license>"), {"package.xml is valid XML"},
                 id="unclosed-tag"),
    pytest.param(_changed("package.xml", "<build_type>ament_python<", "<build_type>ament_cmake<"), {NAMED},
                 id="ament-cmake"),
    pytest.param(_changed("package.xml", f"<name>{PACKAGE}<", "<name>heartbeat<"), {NAMED}, id="other-name"),
    pytest.param(_changed("package.xml", "  <exec_depend>std_msgs</exec_depend>\n", ""), {DEPENDS},
                 id="no-std-msgs-depend"),  # builds, and runs wherever std_msgs happens to be installed
    pytest.param(lambda files: {**files, f"resource/{PACKAGE}": None}, {"the files can be written into src/"},
                 id="marker-is-none"),
    pytest.param(_changed("setup.py", "['package.xml']", "['package.xml', 'launch/heartbeat.launch.py']"),
                 {"colcon build succeeds"}, id="lists-a-missing-file"),
    pytest.param(_changed("package.xml", "student@example.com", "nobody"), {IDENTIFIED}, id="bad-email"),
    pytest.param(NO_ENTRY_POINT, {FINDS}, id="no-entry-point"),
    pytest.param(SCRIPTS_IN_BIN, {FINDS}, id="scripts-in-bin"),
    pytest.param(_changed("setup.py", "heartbeat:main'", "heartbeat:run'"), {SHOWS_NODE},
                 id="wrong-function"),
    pytest.param(_changed(MODULE, "__init__('heartbeat')", "__init__('heartbeat_node')"), {SHOWS_NODE},
                 id="other-node-name"),  # a report, not a WaitTimeout out of the checker
    pytest.param(_changed(MODULE, "self.publisher.publish(", "print("),
                 {f"messages arrive on {TOPIC} from the packaged node"}, id="never-publishes"),
    pytest.param(_changed(MODULE, "except (KeyboardInterrupt, ExternalShutdownException):",
                          "except ExternalShutdownException:"),
                 {CTRL_C_CRITERION}, id="no-keyboard-interrupt"),
]


def test_package_checker_accepts_the_reference_and_every_criterion_has_a_wrong_package(rt):
    report = check_package(reference_package())
    assert report.passed, report.summary()
    assert_reference_criteria("check_package", report)
    assert ONLY_WHEN_FAILED <= _covered(PACKAGE_WRONG)


def test_a_dependency_declared_as_depend_counts_and_a_missing_one_is_named(rt):
    as_depend = _changed("package.xml", "<exec_depend>std_msgs</exec_depend>", "<depend>std_msgs</depend>")
    report = check_package(as_depend(reference_package()))
    assert report.passed, report.summary()
    no_rclpy = _changed("package.xml", "  <exec_depend>rclpy</exec_depend>\n", "")  # std_msgs lacks it
    report = check_package(no_rclpy(reference_package()))
    assert _failed(report) == {DEPENDS}, report.summary()
    depends = _criterion(report, DEPENDS)
    assert "where only std_msgs and what it needs" in depends.detail, depends.detail
    assert "No module named 'rclpy'" in depends.detail and "rclpy" not in depends.hint


def test_the_run_dependencies_of_rclpy_and_std_msgs_follow_the_installed_manifests():
    ros = installed_ros_packages([Path(sys.prefix)])
    rclpy_needs, std_msgs_needs = dependency_closure(["rclpy"], ros), dependency_closure(["std_msgs"], ros)
    assert "std_msgs" not in rclpy_needs and "rclpy" not in std_msgs_needs  # each must be declared
    # a message package brings what its generated Python imports (build_export_depend of rosidl_core_runtime)
    assert {"rosidl_generator_py", "rosidl_parser", "builtin_interfaces"} <= std_msgs_needs
    assert {"rcl_interfaces", "rosgraph_msgs"} <= rclpy_needs
    assert "course_interfaces" not in rclpy_needs | std_msgs_needs


@pytest.mark.parametrize("make_wrong_files, criteria", PACKAGE_WRONG)
def test_package_checker_fails_each_criterion_on_a_wrong_package(rt, make_wrong_files, criteria):
    report = check_package(make_wrong_files(reference_package()))
    assert not report.passed
    assert criteria <= _failed(report), report.summary()


def test_an_unclean_ctrl_c_is_shown_with_the_processes_last_words(rt):
    uncaught = _changed(MODULE, "except (KeyboardInterrupt, ExternalShutdownException):",
                        "except ExternalShutdownException:")
    stop = _criterion(check_package(uncaught(reference_package())), CTRL_C_CRITERION)
    assert not stop.passed, stop.detail
    assert "its last output:" in stop.detail and "KeyboardInterrupt" in stop.detail, stop.detail


def test_a_node_that_ignores_ctrl_c_is_shown_still_running_and_a_check_right_after_waits_it_out(
        rt, capsys):
    ignores = _changed(MODULE, MAIN_BODY, (
        "rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)\n"
        "    signal.signal(signal.SIGINT, lambda *_: print('Ctrl+C ignored', flush=True))\n"
        "    node = Heartbeat()\n    rclpy.spin(node)\n"))
    imports = _changed(MODULE, "import rclpy\n", "import signal\n\nimport rclpy\n"
                       "from rclpy.signals import SignalHandlerOptions\n")
    stop = _criterion(check_package(ignores(imports(reference_package()))), CTRL_C_CRITERION)
    assert not stop.passed, stop.detail
    assert stop.detail.startswith("still running") and "Ctrl+C ignored" in stop.detail, stop.detail
    # The checker then killed it, so it said no goodbye and stays in the graph until its lease ends.
    # The student mends the program and checks again at once: the checker waits that lease out.
    assert NODE in rt.graph_nodes()
    capsys.readouterr()
    again = check_package(reference_package())
    assert not _failed(again), again.summary()
    assert "waiting up to" in capsys.readouterr().out


def _spins_on_after_shutdown(error: str, catches: str = "ExternalShutdownException"):
    """The reference, except that Ctrl+C leaves rclpy's handler alone (no KeyboardInterrupt) and main()
    goes on spinning after ExternalShutdownException, as spin() does when the handler ends the context
    between its check and the wait set: rclpy's shutdown race, made certain. ``error`` is what the
    process does when ``catches`` is raised: spin on into rclpy's own RCLError, or (a wrong program)
    raise an error of its own."""
    loop = (
        "signal.signal(signal.SIGINT, lambda *_: None)  # rclpy's handler still ends the context\n"
        "    rclpy.init(args=args)\n"
        "    node = Heartbeat()\n"
        "    executor = SingleThreadedExecutor()\n"
        "    executor.add_node(node)\n"
        "    try:\n"
        "        while True:\n"
        "            try:\n"
        "                executor.spin_once()  # no timeout: no timer\n"
        f"            except {catches}:\n"
        f"                {error}\n"
        "    except KeyboardInterrupt:\n"
        "        pass\n"
        "    finally:\n"
        "        node.destroy_node()\n"
        "        rclpy.try_shutdown()\n")
    imports = _changed(MODULE, "import rclpy\n", "import signal\n\nimport rclpy\n"
                       "from rclpy.executors import SingleThreadedExecutor\n")
    body = _changed(MODULE, MAIN_BODY, loop)
    return lambda files: body(imports(files))


MAIN_BODY = ("rclpy.init(args=args)\n    node = Heartbeat()\n    try:\n        rclpy.spin(node)\n"
             "    except (KeyboardInterrupt, ExternalShutdownException):\n"
             "        pass  # Ctrl+C or `kill`: leave quietly\n    finally:\n        node.destroy_node()\n"
             "        rclpy.try_shutdown()\n")


def test_rclpy_shutdown_race_on_ctrl_c_is_forgiven_and_nothing_else_is(rt):
    race = check_package(_spins_on_after_shutdown("pass  # the next spin_once makes a wait set")(
        reference_package()))
    stop = _criterion(race, CTRL_C_CRITERION)
    assert stop.passed and "rclpy's own shutdown race" in stop.detail, stop.detail
    assert race.passed, race.summary()
    # The same words, raised by the program. It raises them whichever way spin_once ends, so that rclpy's
    # race (possible at any spin_once under load) ends it from the program's own frame too.
    other = check_package(_spins_on_after_shutdown(
        f"raise RuntimeError({SHUTDOWN_RACE!r}) from None", catches="Exception")(reference_package()))
    stop = _criterion(other, CTRL_C_CRITERION)
    assert not stop.passed and "exit code 1" in stop.detail and "RuntimeError" in stop.detail, stop.detail


def test_package_checker_hint_tells_a_missing_entry_point_from_a_wrong_setup_cfg(rt):
    for make_wrong_files, hint in ((NO_ENTRY_POINT, "console_scripts"), (SCRIPTS_IN_BIN, "install_scripts")):
        failed = [c for c in check_package(make_wrong_files(reference_package())).criteria if not c.passed]
        assert failed[0].name == FINDS and hint in failed[0].hint, failed


def test_package_checker_refuses_to_run_beside_the_notebooks_own_node(rt):
    # The notebook's own /heartbeat node would fake a pass: the checker refuses to run then.
    rt.add(Talker, name="heartbeat", topic="heartbeat", console=False)
    report = check_package(reference_package())
    assert _failed(report) == {NOT_ALONE} and "this notebook's own node" in report.criteria[-1].detail, \
        report.summary()
    rt.remove("/heartbeat")


def test_package_checker_waits_for_a_node_of_another_process_and_then_names_it_running(rt, monkeypatch):
    # Another running process has /heartbeat: it never leaves, so the checker fails after its wait
    # (shortened here: the verdict does not depend on how long it waits).
    monkeypatch.setattr(checker, "LEFTOVER_WAIT_S", 1.0)
    rt.spawn("other_heartbeat", Talker, {"name": "heartbeat", "topic": "heartbeat"}, wait_for=NODE)
    try:
        report = check_package(reference_package())
    finally:
        rt.stop_child("other_heartbeat")
    assert _failed(report) == {NOT_ALONE} and "a running process has it" in report.criteria[-1].detail, \
        report.summary()


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


# ---------------------------------------------------------------------- the exercise's files on disk
WRITEFILE = "%%writefile {my_package_dir}/"
EMPTY_FILE = r"\(my_package_dir / '(\w+)' / '([\w.]+)'\)\.write_text"


def _notebook() -> dict:
    path = os.path.join(REPO, "notebooks", "09_packages_and_interfaces.ipynb")
    with open(path, encoding="utf-8") as handle:
        return json.load(handle)


def test_read_package_gives_the_checker_the_files_a_folder_holds(tmp_path):
    folder = write_package_files(tmp_path / "robot_heartbeat", reference_package())
    (folder / "robot_heartbeat" / "__pycache__").mkdir()
    (folder / "robot_heartbeat" / "__pycache__" / "heartbeat.cpython-311.pyc").write_bytes(b"\x00\xff")
    (folder / ".ipynb_checkpoints").mkdir()
    (folder / ".ipynb_checkpoints" / "setup-checkpoint.py").write_text("stale")
    assert read_package(folder) == reference_package()  # caches and hidden files left out
    (folder / "logo.png").write_bytes(b"\x89PNG\xff\xfe")
    with pytest.raises(CourseError, match="logo.png .* is not UTF-8 text"):
        read_package(folder)
    with pytest.raises(CourseError, match="is not a folder: run the cells that write the package first"):
        read_package(tmp_path / "never_written")
    with pytest.raises(CourseError, match="leaves the package directory"):
        write_package_files(folder, {"../outside.txt": "x"})


def test_the_exercise_cells_write_every_file_of_the_package():
    """The notebook's %%writefile cells and its folder cell make the same files as the reference package."""
    written = set()
    for cell in _notebook()["cells"]:
        text = "".join(cell["source"])
        if cell["cell_type"] == "code" and text.startswith(WRITEFILE):
            written.add(text.split("\n", 1)[0][len(WRITEFILE):])
        elif cell["cell_type"] == "code":  # the empty files, made by the folder cell
            written |= {f"{a}/{b}" for a, b in re.findall(EMPTY_FILE, text)}
    assert written == set(reference_package())


def test_nbgrader_grades_the_files_the_student_wrote(tmp_path):
    """The instructor source has a solution cell right before the checker that writes the reference
    files over the student's; the release keeps only its comment, so the student's files are graded."""
    chapter = grading_source.load_chapter(grading_source.NOTEBOOKS / "09_packages_and_interfaces.ipynb")
    (exercise,) = chapter.graded
    assert exercise.files_reader == "course_helpers.chapters.ch09_packages"
    cells = grading_source.build_source(chapter)["cells"]
    index = next(i for i, c in enumerate(cells)
                 if c["metadata"].get("nbgrader", {}).get("grade_id") == exercise.grade_id)
    answer, check = cells[index], cells[index + 1]
    assert check["metadata"]["nbgrader"]["grade_id"] == exercise.grade_id + "_check"
    assert "check_package(read_package(my_package_dir))" in "".join(check["source"])
    text = "".join(answer["source"])
    skeleton, solution = text.split(grading_source.BEGIN)
    assert "%%writefile cells above" in skeleton and "write_package_files" not in skeleton
    namespace = {"my_package_dir": tmp_path / "robot_heartbeat"}
    exec(compile(solution.split(grading_source.END)[0], "<solution cell>", "exec"), namespace)  # noqa: S102
    assert read_package(tmp_path / "robot_heartbeat") == reference_package()


COVERED = {"check_package": failing(PACKAGE_WRONG) | {NOT_ALONE}}
ONLY_WHEN_FAILING = {"check_package": ONLY_WHEN_FAILED | {NOT_ALONE, STARTS}}
EXEMPT = {"check_package": {
    STARTS: "fails only if the process layer cannot start this venv's Python, or the package's manifest, "
            "read before the build, cannot be read after it; once the executable was found, the process "
            "started is the venv's Python, which then runs the script",
}}
