"""Real rosidl builds of the course's interface package (course_helpers.core.build_interfaces).

Each build runs CMake and the C/C++ compilers for about 20-30 s; nothing is mocked.
Packages are built into temporary prefixes, never into the venv.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import sysconfig
import textwrap
import time
from pathlib import Path

import numpy
import pytest

from course_helpers.core.build_interfaces import (
    BuildResult,
    build_package,
    fix_python_include_paths,
    missing_cmake_packages,
)

REPO_ROOT = Path(__file__).resolve().parents[1]
# Real builds take 20-30 s on a quiet machine and several times that on a busy one. The tests share
# one clean build, so under pytest-xdist they stay on one worker (make test uses --dist loadgroup).
BUILD_TIMEOUT_S = 400
pytestmark = [pytest.mark.xdist_group("rosidl_builds"), pytest.mark.timeout(BUILD_TIMEOUT_S)]

# Run in a new process of the venv, with the temporary prefix in front of every path.
IMPORT_CHECK = textwrap.dedent(
    """
    import course_interfaces
    from geometry_msgs.msg import Point
    from rclpy.serialization import deserialize_message, serialize_message

    from course_interfaces.action import Fibonacci, Navigate
    from course_interfaces.msg import EStop, ExperimentSample, Waypoints
    from course_interfaces.srv import AddTwoInts, PickItem

    request = AddTwoInts.Request(a=2, b=40)
    assert (request.a, request.b) == (2, 40)
    assert AddTwoInts.Response(sum=42).sum == 42

    assert Fibonacci.Goal(order=7).order == 7
    result = Fibonacci.Result()
    result.sequence.append(1)
    result.sequence.extend([1, 2])
    assert list(result.sequence) == [1, 1, 2]
    assert list(Fibonacci.Feedback(partial_sequence=[0, 1]).partial_sequence) == [0, 1]

    route = Waypoints(frame_id="map", max_speed=0.5)
    assert route.goal == Point() and route.goal.x == 0.0
    route.points.append(Point(x=1.0, y=2.0))
    route.goal = Point(x=3.0)
    copy = deserialize_message(serialize_message(route), Waypoints)
    assert copy == route and copy.points[0].y == 2.0

    sample = ExperimentSample(seq=3, stamp_ns=-5, payload=bytes(range(4)))
    assert deserialize_message(serialize_message(sample), ExperimentSample) == sample

    assert Navigate.Goal(target=Point(x=1.0), speed=0.3).target.x == 1.0
    assert not Navigate.Result().success
    assert Navigate.Feedback(progress=0.5).progress == 0.5
    assert PickItem.Request(item_id="sku-1", shelf="A3").shelf == "A3"
    assert PickItem.Response(message="ok").message == "ok"
    assert EStop(engaged=True, source="operator").engaged
    print(course_interfaces.__file__)
    """
)


def run_in_new_process(code: str, result: BuildResult) -> str:
    """Run ``code`` in a new venv Python that sees the package installed by ``result``."""
    env = result.environment()
    assert env["PYTHONPATH"].split(":")[0] == str(result.python_dir)
    assert env["LD_LIBRARY_PATH"].split(":")[0] == str(result.install_prefix / "lib")
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


TINY_PACKAGE = {
    "package.xml": textwrap.dedent("""\
        <?xml version="1.0"?>
        <package format="3">
          <name>tiny_msgs</name>
          <version>0.1.0</version>
          <description>One message, for the rebuild test</description>
          <maintainer email="course@example.com">Course</maintainer>
          <license>Apache-2.0</license>
          <buildtool_depend>ament_cmake</buildtool_depend>
          <buildtool_depend>rosidl_default_generators</buildtool_depend>
          <exec_depend>rosidl_default_runtime</exec_depend>
          <member_of_group>rosidl_interface_packages</member_of_group>
          <export><build_type>ament_cmake</build_type></export>
        </package>
        """),
    "CMakeLists.txt": textwrap.dedent("""\
        cmake_minimum_required(VERSION 3.16)
        project(tiny_msgs)
        find_package(ament_cmake REQUIRED)
        find_package(rosidl_default_generators REQUIRED)
        rosidl_generate_interfaces(${PROJECT_NAME} "msg/Level.msg")
        ament_export_dependencies(rosidl_default_runtime)
        ament_package()
        """),
    "msg/Level.msg": "float32 fill_ratio\n",
}




def write_tiny_package(directory: Path) -> Path:
    """Write the one-message package under ``directory``; return its source folder."""
    source = directory / "tiny_msgs"
    for relative, text in TINY_PACKAGE.items():
        (source / relative).parent.mkdir(parents=True, exist_ok=True)
        (source / relative).write_text(text)
    return source


@pytest.fixture(scope="module")
def clean_build(tmp_path_factory) -> BuildResult:
    """A clean build of a one-message package (the builder is the same for every package;
    ``make setup`` builds the course's own package, checked by the tests below it)."""
    source = write_tiny_package(tmp_path_factory.mktemp("source"))
    return build_package(source, install_prefix=tmp_path_factory.mktemp("prefix"))


@pytest.mark.slow
def test_clean_build_installs_into_the_given_prefix(clean_build):
    prefix = clean_build.install_prefix
    assert clean_build.rebuilt
    assert clean_build.package == "tiny_msgs"
    assert clean_build.python_dir.is_relative_to(prefix)
    assert (clean_build.python_dir / "tiny_msgs" / "msg" / "_level.py").is_file()
    assert (prefix / "lib" / "libtiny_msgs__rosidl_typesupport_fastrtps_c.so").is_file()
    assert (prefix / "share" / "tiny_msgs" / "msg" / "Level.msg").is_file()
    assert clean_build.log_path.is_file()
    assert "-- Installing: " in clean_build.log_path.read_text()


@pytest.mark.slow
def test_new_process_imports_and_uses_the_built_interfaces(clean_build):
    check = ("import tiny_msgs\nfrom rclpy.serialization import deserialize_message, serialize_message\n"
             "from tiny_msgs.msg import Level\nlevel = Level(fill_ratio=0.5)\n"
             "assert deserialize_message(serialize_message(level), Level) == level\n"
             "print(tiny_msgs.__file__)")
    module_file = run_in_new_process(check, clean_build).strip()
    assert Path(module_file).is_relative_to(clean_build.install_prefix)


def test_the_course_interfaces_built_by_setup_work_in_a_new_process():
    done = subprocess.run([sys.executable, "-c", IMPORT_CHECK], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert Path(done.stdout.strip()).is_relative_to(sys.prefix)


@pytest.mark.slow
def test_second_build_with_same_sources_is_a_fast_no_op(clean_build):
    lines: list[str] = []
    started = time.monotonic()
    again = build_package(clean_build.source_dir, install_prefix=clean_build.install_prefix,
                          progress=lines.append)
    assert time.monotonic() - started < 1.0
    assert not again.rebuilt
    assert lines == ["tiny_msgs is up to date (no definition changed)"]


def test_command_line_reports_the_course_interfaces_up_to_date():
    done = subprocess.run([sys.executable, "-m", "course_helpers.core.build_interfaces"],
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "course_interfaces is up to date (no definition changed)" in done.stdout
    assert "example_interfaces is up to date (no definition changed)" in done.stdout


def test_textbook_imports_of_example_interfaces_work():
    code = ("from example_interfaces.srv import AddTwoInts\nfrom example_interfaces.action import Fibonacci\n"
            "feedback = Fibonacci.Feedback()\nfeedback.sequence = [0, 1]\n"
            "print(AddTwoInts.Response(sum=2 + 3).sum, list(feedback.sequence))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["5", "[0,", "1]"]


@pytest.mark.slow
def test_changed_definition_triggers_a_rebuild(tmp_path):
    source = write_tiny_package(tmp_path)
    prefix = tmp_path / "prefix"
    assert build_package(source, install_prefix=prefix).rebuilt
    assert not build_package(source, install_prefix=prefix).rebuilt

    with open(source / "msg" / "Level.msg", "a") as definition:
        definition.write("string bin_id  # added by the test\n")
    changed = build_package(source, install_prefix=prefix)

    assert changed.rebuilt
    check = "from tiny_msgs.msg import Level\nprint(Level(bin_id='A3').bin_id)"
    assert run_in_new_process(check, changed).strip() == "A3"


def run_cli_with_path(tmp_path: Path, tools: list[str]) -> subprocess.CompletedProcess[str]:
    """Run the builder's CLI with a PATH holding only python and the given tools."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "python").symlink_to(sys.executable)
    for tool in tools:
        (bin_dir / tool).symlink_to(shutil.which(tool))
    env = {"PATH": str(bin_dir), "HOME": str(tmp_path)}
    return subprocess.run(
        [sys.executable, "-m", "course_helpers.core.build_interfaces",
         "--prefix", str(tmp_path / "prefix")],
        cwd=REPO_ROOT, env=env, capture_output=True, text=True, timeout=60,
    )  # fmt: skip


def test_missing_cmake_stops_with_what_to_install(tmp_path):
    done = run_cli_with_path(tmp_path, tools=[])
    assert done.returncode != 0
    assert "cmake" in done.stderr and "apt-get install" in done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "prefix" / "lib").exists()


def test_missing_compiler_stops_with_what_to_install(tmp_path):
    done = run_cli_with_path(tmp_path, tools=["cmake", "make"])
    assert done.returncode != 0
    assert "C++ compiler" in done.stderr and "build-essential" in done.stderr
    assert "cmake not found" not in done.stderr
    assert "Traceback" not in done.stderr


def test_include_path_fix_is_idempotent(tmp_path):
    export = tmp_path / "share" / "demo_msgs" / "cmake"
    export.mkdir(parents=True)
    export_file = export / "export_demo_msgs__rosidl_generator_pyExport.cmake"
    export_file.write_text(
        'INTERFACE_INCLUDE_DIRECTORIES "/opt/python/cp311-cp311/include/python3.11;'
        '/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include"\n'
    )
    assert fix_python_include_paths(tmp_path) == [export_file]
    fixed = export_file.read_text()
    assert "/opt/python" not in fixed
    assert sysconfig.get_paths()["include"] in fixed and numpy.get_include() in fixed
    assert fix_python_include_paths(tmp_path) == []
    assert export_file.read_text() == fixed


def test_ros_cmake_packages_needed_by_the_build_are_in_the_venv(tmp_path):
    assert missing_cmake_packages(Path(sys.prefix)) == []
    assert "python_cmake_module" in missing_cmake_packages(tmp_path)
