"""A C++ program on rcl, compiled and run from a notebook cell (chapter 02, a second language).

rclcpp is not on PyPI, but the ROS 2 wheels in this venv carry rcl, the C library that rclcpp and
rclpy are both built on: its headers (``include/rcl/rcl/rcl.h``), its libraries (``lib/librcl.so``),
rmw and rcutils under it, and the C headers and type support libraries of the message packages
(``include/std_msgs/std_msgs/msg/string.h``). :func:`build_rcl_program` compiles one C++ file
against them with this machine's C++ compiler, into this process's private scratch folder;
:func:`run_program` starts the result as a child process of the course, so it inherits the
kernel's environment (``ROS_DOMAIN_ID``, the discovery range, the Fast DDS profile, and the
``LD_LIBRARY_PATH`` that finds the wheels' libraries), is stopped with the stop signal, and dies
with the kernel.

Two things are particular to the wheels:

* every package keeps its headers in ``include/<package>/<package>/``, so each
  ``include/<package>`` folder is an include path;
* the wheels' ``librcl.so`` also needs the Python type support of rcl_interfaces and a few other
  packages, which call into libpython, so the program links this interpreter's shared libpython
  (a program built against a ROS install from apt does not).
"""

from __future__ import annotations

import os
import re
import sys
import sysconfig
from dataclasses import dataclass
from pathlib import Path

from course_helpers.core import processes
from course_helpers.core.build_interfaces import find_compiler
from course_helpers.core.errors import CourseError

PROCESS_GROUP = "rcl_program"
COMPILE_TIMEOUT_S = 120.0  # s; one small file takes about a second
RCL_LIBRARIES = ("rcl", "rcutils", "rmw", "rosidl_runtime_c")
COMPILER_NAMES = ("c++", "g++", "clang++")
NO_COMPILER = ("No C++ compiler found (looked at $CXX, then for c++, g++ and clang++ on PATH), so this "
               "program is not built; install one (Debian/Ubuntu: apt-get install g++) and run the "
               "cell again. The rest of the notebook runs without it.")
NO_LIBPYTHON = ("This Python has no shared libpython, which the PyPI build of rcl needs to link a "
                "program, so this program is not built; use a Python built with --enable-shared "
                "(pyenv: PYTHON_CONFIGURE_OPTS=--enable-shared). The rest of the notebook runs without it.")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


@dataclass(frozen=True)
class RclProgram:
    """A program built by :func:`build_rcl_program`."""

    name: str
    path: str  # the executable
    source_path: str
    command: tuple[str, ...]  # how it was compiled

    def command_line(self) -> str:
        """The compile command (run in the program's folder), with this venv shown as ``$VENV``,
        the shared libpython as ``$LIBPYTHON`` and the include paths folded into one."""
        libpython = next((part for part in self.command if "libpython" in part and "rpath" not in part), "")
        shown, folded = [os.path.basename(self.command[0])], False
        for part in self.command[1:]:
            if part.startswith("-I"):
                if not folded:
                    shown.append("-I$VENV/include/<package> (one per package)")
                folded = True
                continue
            if libpython:
                part = part.replace(libpython, "$LIBPYTHON")
                part = part.replace(os.path.dirname(libpython), "$(dirname $LIBPYTHON)")
            shown.append(part.replace(sys.prefix, "$VENV"))
        return " ".join(shown)


def message_packages() -> list[str]:
    """The message packages whose C headers and type support this venv has, sorted."""
    include, lib = Path(sys.prefix, "include"), Path(sys.prefix, "lib")
    return sorted(d.name for d in include.iterdir() if (d / d.name / "msg").is_dir()
                  and (lib / f"lib{d.name}__rosidl_typesupport_c.so").exists())


def shared_libpython() -> str | None:
    """The path of this interpreter's shared libpython, or None if it was built without one."""
    folders = [sysconfig.get_config_var(name) for name in ("LIBDIR", "LIBPL")]
    names = [sysconfig.get_config_var(name) for name in ("LDLIBRARY", "INSTSONAME")]
    version = sysconfig.get_config_var("LDVERSION") or sysconfig.get_python_version()
    names += [f"libpython{version}.so", f"libpython{version}.so.1.0"]
    for folder in filter(None, folders):
        for name in filter(None, names):
            path = os.path.join(folder, name)
            if ".so" in name and os.path.isfile(path):
                return path
    return None


def compile_command(compiler: str, source: str, output: str, messages: tuple[str, ...],
                    libpython: str) -> list[str]:
    """The command that compiles the file ``source`` into the program ``output`` against rcl and
    the C type support of ``messages``, linking ``libpython`` (see the module's docstring)."""
    include, lib = Path(sys.prefix, "include"), Path(sys.prefix, "lib")
    packages = sorted(d for d in include.iterdir() if (d / d.name).is_dir())
    message_libs = [f"-l{m}__rosidl_{kind}" for m in messages for kind in ("generator_c", "typesupport_c")]
    return [compiler, "-std=c++17", "-O1", "-Wall", source, "-o", output,
            *(f"-I{d}" for d in packages),
            "-Wl,--no-as-needed", libpython, "-Wl,--as-needed", f"-Wl,-rpath,{os.path.dirname(libpython)}",
            f"-L{lib}", *(f"-l{name}" for name in RCL_LIBRARIES), *message_libs]


def build_rcl_program(name: str, source: str, messages: tuple[str, ...] = ("std_msgs",),
                      verbose: bool = False) -> RclProgram | None:
    """Compile the C++ ``source`` into the program ``name`` against rcl and the C type support of
    ``messages``.

    Args:
        name: the program's name, a C identifier (``rcl_talker``).
        source: the program's C++ text (one translation unit).
        messages: the message packages it uses, from :func:`message_packages`.
        verbose: also print the compile command.

    Returns:
        The :class:`RclProgram`; None, after one line saying what is missing, when this machine has
        no C++ compiler or no shared libpython. Raises :class:`CourseError` with the compiler's
        messages when the source does not compile.
    """
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise CourseError(f"a program name must be a C identifier such as 'rcl_talker', got {name!r}")
    if not isinstance(source, str) or "main" not in source:
        raise CourseError("source must be the program's C++ text, with a main() function")
    available = message_packages()
    unknown = [m for m in messages if m not in available]
    if unknown:
        raise CourseError(f"no C type support for {', '.join(map(repr, unknown))} in this venv; "
                          f"available: {', '.join(available)}")
    compiler = find_compiler("CXX", COMPILER_NAMES)
    if compiler is None:
        print(NO_COMPILER)
        return None
    libpython = shared_libpython()
    if libpython is None:
        print(NO_LIBPYTHON)
        return None
    folder = os.path.join(processes.log_dir(), "rcl_programs")  # private to this process
    os.makedirs(folder, mode=0o700, exist_ok=True)
    source_path, output = os.path.join(folder, f"{name}.cpp"), os.path.join(folder, name)
    Path(source_path).write_text(source)
    command = compile_command(compiler, f"{name}.cpp", name, tuple(messages), libpython)
    code, printed = processes.run(command, cwd=folder, timeout=COMPILE_TIMEOUT_S)
    if code != 0:
        raise CourseError(f"{name}.cpp did not compile ({os.path.basename(compiler)} exited with code "
                          f"{code}). The compiler said:\n{printed[-3000:]}")
    program = RclProgram(name, output, source_path, tuple(command))
    if verbose:
        print(program.command_line())
    if printed.strip():
        print(printed)  # the compiler's warnings
    return program


def run_program(label: str, program: RclProgram, *args: str) -> processes.ChildProcess:
    """Start ``program`` with the command-line ``args`` as the course's child process ``label``.

    Starting a label that runs already stops the old process first. The process gets the kernel's
    environment and its stop signal is SIGTERM; ``child.stop()`` returns its exit code.
    """
    if not isinstance(program, RclProgram):
        raise CourseError(f"run_program needs what build_rcl_program returned, got {type(program).__name__}")
    return processes.start(label, processes.program_argv(program.path, *args), group=PROCESS_GROUP,
                           channel=False)
