"""Build a ROS 2 interface package (.msg/.srv/.action) with the real rosidl toolchain.

The chapters import the course's own interfaces (``course_interfaces``): 04
``AddTwoInts``, 05 ``Fibonacci`` and ``Navigate``, 08b ``ExperimentSample``, 09
``Waypoints``, 10 the capstone's ``PickItem`` and ``EStop``. Set-up also builds a
stand-in for ``example_interfaces`` so textbook code runs as written. Chapter 09
teaches how such a package is built and calls :func:`build_package` on a
student's own package in a temporary directory.

The toolchain is the one from the ROS 2 Jazzy PyPI wheels installed in this
virtual environment: CMake + ament_cmake + rosidl_default_generators, with
``AMENT_PREFIX_PATH`` pointing at the venv prefix (``sys.prefix``).  Two things
are taken care of here:

* the wheels' ``*__rosidl_generator_pyExport.cmake`` files name the include
  directories of the machine the wheels were built on (``/opt/python/...``);
  they are rewritten, once, to this interpreter's and numpy's include dirs;
* a build is skipped when no definition changed: a digest of the package's
  files (and the Python version) is kept in a stamp file in the install prefix.

Command line (builds ``interfaces/course_interfaces`` into the venv, after which
a new Python process of the venv can ``from course_interfaces.srv import
AddTwoInts``; the venv's bootstrapper already puts ``sys.prefix/lib`` on
``LD_LIBRARY_PATH``)::

    python -m course_helpers.core.build_interfaces [--force] [--prefix PREFIX]
"""

from __future__ import annotations

import argparse
import fcntl
import hashlib
import json
import os
import re
import shutil
import sys
import sysconfig
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from course_helpers.core import processes

__all__ = [
    "BuildResult",
    "InterfaceBuildError",
    "MissingToolError",
    "build_package",
    "find_compiler",
    "fix_python_include_paths",
    "main",
]

REPO_ROOT = Path(__file__).resolve().parents[2]
INTERFACES_DIR = REPO_ROOT / "interfaces"
COURSE_INTERFACES_DIR = INTERFACES_DIR / "course_interfaces"
# Built by set-up: the course's own package, and a stand-in for example_interfaces (not on PyPI).
SETUP_PACKAGES = (INTERFACES_DIR / "example_interfaces", COURSE_INTERFACES_DIR)

# Bump when the build recipe changes, so that every installed package is rebuilt.
RECIPE_VERSION = 1
STAMP_NAME = ".interface_build_stamp.json"
LOG_NAME = "build.log"
LOG_TAIL_LINES = 40
STEP_TIMEOUT_S = 600.0  # s; a CMake step that takes longer is stopped (a full build takes about 25 s)
CMAKE_STEPS = ("configure", "build", "install")  # cmake_commands()' steps, in order
BUILD_LIMIT_S = len(CMAKE_STEPS) * STEP_TIMEOUT_S  # s; the most a build runs before a step's limit stops it
# Directories of a source tree that are not part of the package's definition.
IGNORED_DIRS = {"build", "install", "log", "__pycache__"}

INSTALL_HINT = "On Debian/Ubuntu: apt-get install cmake make g++ (or: apt-get install cmake build-essential)"

Progress = Callable[[str], None]


class InterfaceBuildError(RuntimeError):
    """The interface package could not be built; the message says why and where the log is."""


class MissingToolError(InterfaceBuildError):
    """A tool the build needs (cmake, make, compilers, Python headers, a ROS wheel) is missing."""


@dataclass(frozen=True)
class BuildResult:
    """What :func:`build_package` did and where the package was installed."""

    package: str
    source_dir: Path
    install_prefix: Path
    build_dir: Path
    log_path: Path
    rebuilt: bool
    seconds: float

    @property
    def python_dir(self) -> Path:
        """The site-packages directory of the prefix, which holds the package's Python module."""
        return python_install_dir(self.install_prefix)

    @property
    def library_dir(self) -> Path:
        """The directory of the generated C/C++ and type support libraries."""
        return self.install_prefix / "lib"

    def environment(self, base: dict[str, str] | None = None) -> dict[str, str]:
        """Environment for a new process of this venv that imports the package from this prefix.

        Not needed for the venv itself. A running process cannot pick up a new library
        directory, so a package built into another prefix is imported in a new process.
        """
        env = dict(os.environ if base is None else base)
        env["PYTHONPATH"] = _prepend_path(env.get("PYTHONPATH"), self.python_dir)
        env["LD_LIBRARY_PATH"] = _prepend_path(env.get("LD_LIBRARY_PATH"), self.library_dir)
        env["AMENT_PREFIX_PATH"] = _prepend_path(env.get("AMENT_PREFIX_PATH"), self.install_prefix)
        if str(Path(sys.prefix) / "lib") in env["LD_LIBRARY_PATH"].split(os.pathsep):
            # The venv's libraries are already there: tell ros_wheels_bootstrapper so that it
            # does not rebuild the path, whose order (this prefix first) it does not keep.
            env["_ROS_WHEELS_BOOTSTRAP_COMPLETE"] = "1"
        return env


def build_package(
    source_dir: str | os.PathLike[str],
    install_prefix: str | os.PathLike[str] = sys.prefix,
    build_dir: str | os.PathLike[str] | None = None,
    force: bool = False,
    progress: Progress | None = None,
) -> BuildResult:
    """Build and install the interface package in ``source_dir`` into ``install_prefix``.

    Skipped (``rebuilt=False``) when the installed package was built from the same
    definitions with the same Python, unless ``force`` is true, which also starts
    from an empty build directory.  ``progress`` receives one line per step.
    Raises :class:`MissingToolError` or :class:`InterfaceBuildError`.
    """
    report = progress or (lambda _line: None)
    started = time.monotonic()
    source = Path(source_dir).resolve()
    prefix = Path(install_prefix).resolve()
    package = read_package_name(source)
    build = Path(build_dir).resolve() if build_dir else default_build_dir(prefix, package)
    build.mkdir(parents=True, exist_ok=True)
    log_path = build / LOG_NAME

    with _exclusive_lock(build / ".lock"):
        stamp = build_stamp(source, build)
        if not force and is_up_to_date(prefix, package, stamp):
            report(f"{package} is up to date (no definition changed)")
            return BuildResult(package, source, prefix, build, log_path, False, time.monotonic() - started)
        check_toolchain()
        fix_python_include_paths(Path(sys.prefix))
        _prepare_build_dir(build, source, clean=force)
        _run_cmake_steps(source, prefix, build, log_path, report)
        write_stamp(prefix, package, stamp)

    seconds = time.monotonic() - started
    report(f"{package} built and installed into {prefix} in {seconds:.1f} s")
    return BuildResult(package, source, prefix, build, log_path, True, seconds)


# --- the package and its stamp ---------------------------------------------------------


def read_package_name(source: Path) -> str:
    """The ``<name>`` of the package.xml in ``source``."""
    manifest = source / "package.xml"
    if not manifest.is_file():
        raise InterfaceBuildError(f"{source} is not a ROS package: it has no package.xml")
    name = ET.parse(manifest).getroot().findtext("name")
    if not name or not name.strip():
        raise InterfaceBuildError(f"{manifest} has no <name>")
    return name.strip()


def default_build_dir(prefix: Path, package: str) -> Path:
    """Where the package is built when no build directory is given: ``PREFIX/build/PACKAGE``."""
    return prefix / "build" / package


def python_install_dir(prefix: Path) -> Path:
    """The purelib directory under ``prefix``, computed as ament_cmake_python does."""
    schemes = sysconfig.get_scheme_names()
    kwargs: dict = {"vars": {"base": str(prefix)}}
    if "deb_system" in schemes or "osx_framework_library" in schemes:
        kwargs["scheme"] = "posix_prefix"
    elif "rpm_prefix" in schemes:
        kwargs["scheme"] = "rpm_prefix"
    return Path(sysconfig.get_path("purelib", **kwargs))


def _definition_files(source: Path, build: Path) -> Iterator[Path]:
    """The package's files, sorted, leaving out hidden files and build output."""
    for path in sorted(source.rglob("*")):
        relative = path.relative_to(source)
        if any(part.startswith(".") or part in IGNORED_DIRS for part in relative.parts):
            continue
        if path.is_file() and build not in path.parents:
            yield path


def build_stamp(source: Path, build: Path) -> dict[str, object]:
    """What the installed package must have been built from to be up to date."""
    digest = hashlib.sha256()
    for path in _definition_files(source, build):
        digest.update(path.relative_to(source).as_posix().encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return {
        "recipe": RECIPE_VERSION,
        "python": sys.version.split()[0],
        "source_digest": digest.hexdigest(),
    }


def _stamp_path(prefix: Path, package: str) -> Path:
    return prefix / "share" / package / STAMP_NAME


def is_up_to_date(prefix: Path, package: str, stamp: dict[str, object]) -> bool:
    """True when the stamp matches and the installed Python module and libraries exist."""
    try:
        recorded = json.loads(_stamp_path(prefix, package).read_text())
    except (OSError, ValueError):
        return False
    installed = [
        python_install_dir(prefix) / package / "__init__.py",
        prefix / "lib" / f"lib{package}__rosidl_typesupport_c.so",
        prefix / "lib" / f"lib{package}__rosidl_generator_py.so",
    ]
    return recorded == stamp and all(path.exists() for path in installed)


def write_stamp(prefix: Path, package: str, stamp: dict[str, object]) -> None:
    path = _stamp_path(prefix, package)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(stamp, indent=2) + "\n")


# --- the toolchain ------------------------------------------------------------------------


def find_compiler(env_var: str, candidates: tuple[str, ...]) -> str | None:
    """The path of the compiler named by ``env_var`` (CC, CXX) if set, else of the first of
    ``candidates`` on PATH; None if there is none."""
    chosen = os.environ.get(env_var)
    if chosen:
        return shutil.which(chosen.split()[0])
    return next((found for name in candidates if (found := shutil.which(name))), None)


def missing_tools() -> list[str]:
    """The tools a build needs that are not on this machine (empty when all are there)."""
    missing = []
    if not shutil.which("cmake"):
        missing.append("cmake")
    if not (shutil.which("make") or shutil.which("ninja")):
        missing.append("make")
    if not find_compiler("CC", ("cc", "gcc", "clang")):
        missing.append("a C compiler (gcc)")
    if not find_compiler("CXX", ("c++", "g++", "clang++")):
        missing.append("a C++ compiler (g++)")
    return missing


def check_toolchain() -> None:
    """Raise :class:`MissingToolError`, saying what to install, when a build tool is missing."""
    missing = missing_tools()
    if missing:
        raise MissingToolError(
            f"Cannot build ROS interfaces: {', '.join(missing)} not found on PATH.\n{INSTALL_HINT}"
        )
    headers = Path(sysconfig.get_paths()["include"]) / "Python.h"
    if not headers.is_file():
        raise MissingToolError(
            f"Cannot build ROS interfaces: the Python headers ({headers}) are missing.\n"
            f"On Debian/Ubuntu: apt-get install python{sys.version_info[0]}.{sys.version_info[1]}"
            "-dev (or the -dev package of the Python this venv was made from)"
        )
    absent = missing_cmake_packages(Path(sys.prefix))
    if absent:
        wheels = " ".join(f"ros-jazzy-{name.replace('_', '-')}" for name in absent)
        raise MissingToolError(
            f"Cannot build ROS interfaces: the CMake packages {', '.join(absent)} are not in "
            f"{sys.prefix}.\nInstall their wheels: pip install {wheels} (see environment.txt)"
        )


# CMake packages of the ROS wheels that rosidl_generate_interfaces() needs at configure time.
REQUIRED_CMAKE_PACKAGES = ("ament_cmake", "rosidl_default_generators", "python_cmake_module")


def missing_cmake_packages(ros_prefix: Path) -> list[str]:
    """The required ROS CMake packages that have no ``share/NAME/cmake/NAMEConfig.cmake``."""
    return [
        name
        for name in REQUIRED_CMAKE_PACKAGES
        if not (ros_prefix / "share" / name / "cmake" / f"{name}Config.cmake").is_file()
    ]


# Include dirs of the wheel-building machine, e.g. /opt/python/cp311-cp311/include/python3.11
# and /opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include.
_BUILD_MACHINE_INCLUDE = re.compile(r"/opt/python/[^/;\"]+/(?P<rest>[^;\"]*)")


def _local_include_dir(match: re.Match[str]) -> str:
    import numpy  # only needed here: keeps the no-op path fast

    if "numpy" in match["rest"]:
        return numpy.get_include()
    return sysconfig.get_paths()["include"]


def fix_python_include_paths(ros_prefix: Path) -> list[Path]:
    """Point the wheels' rosidl_generator_py CMake exports at this machine's include dirs.

    Idempotent: files that are already right are left alone. Returns the files changed.
    """
    changed = []
    for export in sorted(ros_prefix.glob("share/**/*__rosidl_generator_pyExport*.cmake")):
        text = export.read_text()
        fixed = _BUILD_MACHINE_INCLUDE.sub(_local_include_dir, text)
        if fixed != text:
            export.write_text(fixed)
            changed.append(export)
    return changed


# --- the build -----------------------------------------------------------------------------


@contextmanager
def _exclusive_lock(path: Path) -> Iterator[None]:
    """Serialise builds sharing a build directory (e.g. notebooks run side by side)."""
    with open(path, "w") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _cached_source_dir(build: Path) -> Path | None:
    cache = build / "CMakeCache.txt"
    if not cache.is_file():
        return None
    for line in cache.read_text(errors="replace").splitlines():
        if line.startswith("CMAKE_HOME_DIRECTORY:"):
            return Path(line.partition("=")[2])
    return None


def _prepare_build_dir(build: Path, source: Path, clean: bool) -> None:
    """Empty the build directory when asked to, or when it was configured for other sources."""
    cached = _cached_source_dir(build)
    if clean or (cached is not None and cached != source):
        for entry in build.iterdir():
            if entry.name == ".lock":
                continue
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()


def _prepend_path(current: str | None, *entries: Path | str) -> str:
    parts = [str(entry) for entry in entries]
    parts += [part for part in (current or "").split(os.pathsep) if part and part not in parts]
    return os.pathsep.join(parts)


def build_environment(prefix: Path) -> dict[str, str]:
    """The environment of the CMake steps: the venv's ROS packages and the target prefix."""
    env = dict(os.environ)
    ros_prefix = Path(sys.prefix)
    env["AMENT_PREFIX_PATH"] = _prepend_path(env.get("AMENT_PREFIX_PATH"), prefix, ros_prefix)
    env["CMAKE_PREFIX_PATH"] = _prepend_path(env.get("CMAKE_PREFIX_PATH"), prefix, ros_prefix)
    env["LD_LIBRARY_PATH"] = _prepend_path(env.get("LD_LIBRARY_PATH"), prefix / "lib", ros_prefix / "lib")
    env["PATH"] = _prepend_path(env.get("PATH"), Path(sys.executable).parent)
    return env


def cmake_commands(source: Path, prefix: Path, build: Path) -> list[tuple[str, list[str]]]:
    """The configure, build and install steps, each with a short name."""
    generator = [] if shutil.which("make") else ["-G", "Ninja"]
    configure = [
        "cmake", "-S", str(source), "-B", str(build), *generator,
        f"-DCMAKE_INSTALL_PREFIX={prefix}",
        f"-DPython3_EXECUTABLE={sys.executable}",
        "-DPython3_FIND_STRATEGY=LOCATION",
        "-DCMAKE_BUILD_TYPE=Release",
        "-DBUILD_TESTING=OFF",
    ]  # fmt: skip
    jobs = str(os.cpu_count() or 2)
    commands = {
        "configure": configure,
        "build": ["cmake", "--build", str(build), "--parallel", jobs],
        "install": ["cmake", "--install", str(build)],
    }
    return [(step, commands[step]) for step in CMAKE_STEPS]


def _log_tail(log_path: Path, lines: int = LOG_TAIL_LINES) -> str:
    return "\n".join(log_path.read_text(errors="replace").splitlines()[-lines:])


def _run_cmake_steps(source: Path, prefix: Path, build: Path, log_path: Path, report: Progress) -> None:
    """Run configure, build and install, appending all output to ``log_path``."""
    env = build_environment(prefix)
    with open(log_path, "w") as log:
        for name, command in cmake_commands(source, prefix, build):
            report(f"{name} ... (log: {log_path})")
            log.write(f"$ {' '.join(command)}\n")
            log.flush()
            code, _output = processes.run(command, env=env, log=log, timeout=STEP_TIMEOUT_S)
            if code != 0:
                log.flush()
                raise InterfaceBuildError(
                    f"The {name} step failed (exit code {code}). "
                    f"Last lines of {log_path}:\n{_log_tail(log_path)}\n"
                    f"Full log: {log_path}"
                )


# --- command line --------------------------------------------------------------------------


def _parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="python -m course_helpers.core.build_interfaces",
        description="Build the course's ROS 2 interface packages with rosidl and install them.",
    )
    parser.add_argument("--force", action="store_true", help="rebuild from scratch")
    parser.add_argument(
        "--prefix", default=sys.prefix, help="install prefix (default: this venv, %(default)s)"
    )
    parser.add_argument(
        "--source", action="append",
        help="an interface package to build; repeat for several (default: every package set-up "
             "builds: interfaces/example_interfaces and interfaces/course_interfaces)",
    )
    parser.add_argument("--build-dir", default=None, help="build directory (default: PREFIX/build/NAME)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the process exit code."""
    args = _parse_args(argv)
    for source in args.source or SETUP_PACKAGES:
        try:
            result = build_package(
                source, args.prefix, args.build_dir, force=args.force,
                progress=lambda line: print(line, flush=True),
            )  # fmt: skip
        except MissingToolError as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        except InterfaceBuildError as error:
            print(f"error: {error}", file=sys.stderr)
            return 1
        if result.rebuilt:
            print(f"Python module: {result.python_dir / result.package}")
            print(f"Libraries:     {result.library_dir}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
