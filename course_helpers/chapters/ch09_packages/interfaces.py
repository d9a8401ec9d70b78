"""New interface packages: write them, build them with rosidl, use them in this kernel and in others.

* :func:`create_interface_package` writes an interface package (``.msg``, ``.srv``,
  ``.action``, package.xml, CMakeLists.txt);
* :func:`build_interface_package` builds it with rosidl into a temporary prefix, such as
  :func:`kernel_prefix`, which lasts as long as this process, so that running the notebook
  again with the same definitions finds the package up to date instead of building it again;
* :func:`load_interfaces` imports the generated classes into the running kernel, and
  :func:`interface_env` gives a new process what it needs to import them;
* :class:`MessagePublisher` is a child-process target that publishes such a new message
  from another process.
"""

from __future__ import annotations

import atexit
import ctypes
import hashlib
import importlib
import os
import re
import shutil
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path

from rclpy.node import Node

from course_helpers.chapters.ch09_packages.environment import prepend_env
from course_helpers.chapters.ch09_packages.package_files import (
    check_package_name,
    interface_cmakelists,
    interface_package_xml,
)
from course_helpers.core import scratch_dirs
from course_helpers.core.build_interfaces import BuildResult, build_package
from course_helpers.core.errors import CourseError
from course_helpers.core.validation import resolve_interface

INTERFACE_NAME_RE = re.compile(r"^[A-Z][A-Za-z0-9]*$")
KINDS = ("msg", "srv", "action")
# The order in which a package's C libraries depend on each other (each needs the ones before it).
_LIBRARY_ORDER = ("generator_c", "typesupport_introspection_c", "typesupport_fastrtps_c",
                  "typesupport_c", "generator_py")

# Interface packages imported into this process: name -> digest of their definitions.
_loaded_interfaces: dict[str, str] = {}
# The folder of kernel_prefix(): made on first use, removed when this process exits.
_kernel_dir: Path | None = None


def kernel_prefix(package: str) -> Path:
    """An install prefix for ``package`` that lasts until this process (the kernel) exits.

    A workspace is deleted at the end of the chapter, but the kernel keeps the libraries it
    loaded from the prefix; and running the notebook again with unchanged definitions finds
    the package in this prefix up to date, so it is not built twice. Returns
    ``<temporary folder>/<package>/install``; the build folder goes beside it.
    """
    global _kernel_dir
    check_package_name(package)
    if _kernel_dir is None or not _kernel_dir.is_dir():
        _kernel_dir = Path(scratch_dirs.private_dir("ch09_interfaces"))  # swept if the kernel is killed
        atexit.register(shutil.rmtree, _kernel_dir, True)
    return _kernel_dir / package / "install"


def create_interface_package(parent_dir: str | os.PathLike, name: str,
                             messages: dict[str, str] | None = None,
                             services: dict[str, str] | None = None,
                             actions: dict[str, str] | None = None,
                             dependencies: tuple[str, ...] | list[str] = ()) -> Path:
    """Write an interface package under ``parent_dir`` (an old one of that name is replaced).

    Args:
        parent_dir: the folder to write ``NAME/`` into (a workspace's ``src/``).
        name: the package name (REP 144).
        messages, services, actions: CamelCase name -> definition text;
            ``messages={'BinLevel': 'string bin_id\\nfloat32 fill_ratio'}`` writes ``msg/BinLevel.msg``.
        dependencies: other interface packages the definitions use (e.g. 'geometry_msgs').

    Returns:
        The package directory (with package.xml, CMakeLists.txt and msg/ srv/ action/).
    """
    check_package_name(name)
    kinds = dict(zip(KINDS, (messages or {}, services or {}, actions or {}), strict=True))
    if not any(kinds.values()):
        raise CourseError("give at least one definition: messages={'Name': 'int32 field'}")
    for definitions in kinds.values():
        for interface in definitions:
            if not INTERFACE_NAME_RE.match(interface):
                raise CourseError(f"interface names are CamelCase like 'BinLevel', got {interface!r}")
    package_dir = Path(parent_dir) / name
    if package_dir.exists():
        shutil.rmtree(package_dir)
    listed = []
    for kind, definitions in kinds.items():
        for interface, text in sorted(definitions.items()):
            path = package_dir / kind / f"{interface}.{kind}"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(textwrap.dedent(text).strip() + "\n")
            listed.append(f"{kind}/{interface}.{kind}")
    deps = list(dependencies)
    (package_dir / "CMakeLists.txt").write_text(interface_cmakelists(name, listed, deps))
    (package_dir / "package.xml").write_text(interface_package_xml(name, deps))
    return package_dir


def build_interface_package(source_dir: str | os.PathLike, install_prefix: str | os.PathLike,
                            progress: Callable[[str], None] | None = None) -> BuildResult:
    """Build the interface package in ``source_dir`` with rosidl (CMake) into ``install_prefix``.

    ``colcon build`` would run the same CMake configure/build/install steps for a package
    whose build type is ament_cmake. The build folder is ``install_prefix``'s sibling
    ``build_interfaces/NAME``; a package already installed there from the same definitions
    is not built again (``BuildResult.rebuilt`` is False). ``progress`` gets a line per step,
    then 'done' or 'FAILED'. Returns the :class:`~course_helpers.core.build_interfaces.BuildResult`.
    """
    prefix = Path(install_prefix)
    report = progress or (lambda _line: None)
    report("rosidl: generating and compiling")
    try:
        result = build_package(source_dir, prefix, build_dir=prefix.parent / "build_interfaces"
                               / Path(source_dir).name, progress=progress)
    except Exception:
        report("FAILED")
        raise
    report("done")
    return result


def interface_digest(source_dir: str | os.PathLike) -> str:
    """A digest of an interface package's definition files (to notice changed definitions)."""
    digest = hashlib.sha256()
    for path in sorted(Path(source_dir).rglob("*")):
        if path.suffix in (".msg", ".srv", ".action") and path.is_file():
            digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


def load_interfaces(result: BuildResult, kind: str = "msg"):
    """Import a freshly built interface package into this (already running) process.

    A running process cannot learn a new library directory (``LD_LIBRARY_PATH`` is read
    at start-up), so the package's C libraries are loaded by path first, then the Python
    module is imported from the prefix. Returns the module ``PACKAGE.KIND`` (e.g.
    ``warehouse_msgs.msg``). A package that is already loaded with other definitions needs a
    kernel restart; new processes (``rt.spawn(..., env=interface_env(result))``) always get
    the new ones.
    """
    if kind not in KINDS:
        raise CourseError(f"kind must be 'msg', 'srv' or 'action', got {kind!r}")
    package = result.package
    digest = interface_digest(result.source_dir)
    loaded = _loaded_interfaces.get(package)
    if loaded is not None and loaded != digest:
        raise CourseError(
            f"{package} is already loaded in this kernel with other definitions; a running "
            "process cannot swap compiled libraries. Restart the kernel to use the new ones "
            "here (child processes started now already see them).")
    if loaded is None:
        if package in sys.modules:
            raise CourseError(f"a module called {package!r} is already imported; choose another "
                              "package name")
        lib = Path(result.library_dir)
        prepend_env("LD_LIBRARY_PATH", str(lib))
        for suffix in _LIBRARY_ORDER:
            path = lib / f"lib{package}__rosidl_{suffix}.so"
            if path.is_file():
                ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)
        python_dir = str(result.python_dir)
        if python_dir not in sys.path:
            sys.path.insert(0, python_dir)
        importlib.invalidate_caches()
        _loaded_interfaces[package] = digest
    prepend_env("AMENT_PREFIX_PATH", str(result.install_prefix))  # `ros2 interface show` finds it
    return importlib.import_module(f"{package}.{kind}")


def interface_env(result: BuildResult) -> dict[str, str]:
    """The environment variables a new process needs to import the package built by ``result``
    (pass them as ``env=`` to ``rt.spawn``)."""
    full = result.environment()
    keys = ("PYTHONPATH", "LD_LIBRARY_PATH", "AMENT_PREFIX_PATH", "_ROS_WHEELS_BOOTSTRAP_COMPLETE")
    return {k: full[k] for k in keys if k in full}


class MessagePublisher(Node):
    """Publishes a message of any installed (or freshly built) type from a timer.

    Args:
        type_name: the message type, e.g. 'warehouse_msgs/msg/BinLevel'.
        topic: the topic to publish on.
        fields: field name -> value for every message.
        rate_hz: messages per second.
        name, namespace: the node's name and namespace.
        counter_field: an integer field that counts up from 0, one per message.

    A child-process target: ``rt.spawn('bin_sensor', MessagePublisher, params={...},
    env=interface_env(built))``.
    """

    def __init__(self, type_name: str, topic: str, fields: dict | None = None, rate_hz: float = 5.0,
                 name: str = "message_publisher", counter_field: str | None = None, namespace: str = ""):
        msg_type = resolve_interface(type_name, "msg")  # a wrong name fails before the node exists
        super().__init__(name, namespace=namespace)
        self.msg_type = msg_type
        self.fields = dict(fields or {})
        self.counter_field = counter_field
        self.count = 0
        self.publisher = self.create_publisher(msg_type, topic, 10)
        self.timer = self.create_timer(1.0 / rate_hz, self.publish_one)  # period in seconds

    def publish_one(self) -> None:
        msg = self.msg_type(**self.fields)
        if self.counter_field:
            setattr(msg, self.counter_field, self.count)
        self.publisher.publish(msg)
        self.count += 1
