"""The files of a ROS 2 package as text: what ``ros2 pkg create`` writes, and how package.xml is read.

* :func:`ament_python_files` gives every file of an ament_python package (package.xml,
  setup.py, setup.cfg, the ament index marker and the node module);
  :func:`package_xml`, :func:`setup_py` and :func:`setup_cfg` write one file each;
* :func:`interface_package_xml` and :func:`interface_cmakelists` write the two build files
  of an interface package (ament_cmake + rosidl);
* :func:`read_manifest` reads the name, build type and dependencies of a package.xml;
* :func:`read_package` reads a package's folder into the files it holds (relative path -> text), the
  form :func:`course_helpers.checks.ch09_packages.check_package` takes, and :func:`write_package_files`
  writes such files into a folder.
"""

from __future__ import annotations

import re
import textwrap
import xml.etree.ElementTree as ET
from pathlib import Path

from course_helpers.core.errors import CourseError

PACKAGE_NAME_RE = re.compile(r"^[a-z][a-z0-9_]*$")  # REP 144: lower case, digits, underscores
MAINTAINER = "Course Student"
MAINTAINER_EMAIL = "student@example.com"

# What `ros2 pkg create --node-name` puts in the node's module before you edit it.
NODE_TEMPLATE = """\
def main():
    print('Hi from {package}.')


if __name__ == '__main__':
    main()
"""


def check_package_name(name: str) -> str:
    """Return ``name`` if it is a valid package name (REP 144); raise CourseError if not."""
    if not isinstance(name, str) or not PACKAGE_NAME_RE.match(name):
        raise CourseError(f"package names are lower case letters, digits and underscores, "
                          f"starting with a letter (REP 144), e.g. 'warehouse_tools'; got {name!r}")
    return name


def ament_python_files(name: str, node_name: str, dependencies: list[str] | tuple[str, ...] = ("rclpy",),
                       description: str = "A package made in chapter 09", node_source: str | None = None,
                       executable: str | None = None) -> dict[str, str]:
    """The files of an ament_python package, as ``ros2 pkg create --build-type ament_python
    --node-name NODE_NAME NAME --dependencies ...`` writes them.

    Args:
        name: the package name (REP 144).
        node_name: the node module's name, ``NAME/NODE_NAME.py``.
        dependencies: the packages the node imports (``<exec_depend>`` lines).
        description: package.xml's and setup.py's description.
        node_source: the node module's Python source, with a ``main()``; default: a small template.
        executable: the console script's name (default: ``node_name``); it runs ``NAME.NODE_NAME:main``.

    Returns:
        Relative path -> file text.
    """
    check_package_name(name)
    if not isinstance(node_name, str) or not node_name.isidentifier():
        raise CourseError(f"node_name must be a Python module name like 'battery_monitor', "
                          f"got {node_name!r}")
    if node_source is not None and (not isinstance(node_source, str) or "def main" not in node_source):
        raise CourseError("node_source must be the module's Python source, with a main() "
                          "function that the console script calls")
    executable = executable or node_name
    return {
        "package.xml": package_xml(name, description, list(dependencies)),
        "setup.py": setup_py(name, description, {executable: f"{name}.{node_name}:main"}),
        "setup.cfg": setup_cfg(name),
        f"resource/{name}": "",
        f"{name}/__init__.py": "",
        f"{name}/{node_name}.py": textwrap.dedent(node_source or NODE_TEMPLATE.format(
            package=name)).lstrip("\n"),
    }


def package_xml(name: str, description: str, dependencies: list[str],
                maintainer: str = MAINTAINER, email: str = MAINTAINER_EMAIL) -> str:
    """A format-3 package.xml for an ament_python package with ``<exec_depend>`` on ``dependencies``."""
    depends = "\n".join(f"  <exec_depend>{dep}</exec_depend>" for dep in dependencies)
    return textwrap.dedent(f"""\
        <?xml version="1.0"?>
        <?xml-model href="http://download.ros.org/schema/package_format3.xsd" schematypens="http://www.w3.org/2001/XMLSchema"?>
        <package format="3">
          <name>{name}</name>
          <version>0.1.0</version>
          <description>{description}</description>
          <maintainer email="{email}">{maintainer}</maintainer>
          <license>Apache-2.0</license>

        {{depends}}

          <export>
            <build_type>ament_python</build_type>
          </export>
        </package>
        """).replace("{depends}", depends)


def setup_py(name: str, description: str, console_scripts: dict[str, str]) -> str:
    """A setup.py that installs the package marker, package.xml and the console scripts
    (``{'heartbeat': 'robot_heartbeat.heartbeat:main'}``)."""
    scripts = "\n".join(f"            '{exe} = {target}'," for exe, target in console_scripts.items())
    return textwrap.dedent(f"""\
        from setuptools import setup

        package_name = '{name}'

        setup(
            name=package_name,
            version='0.1.0',
            packages=[package_name],
            data_files=[
                # the marker that lets ament (and `ros2 run`) find the package
                ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
                ('share/' + package_name, ['package.xml']),
            ],
            install_requires=['setuptools'],
            zip_safe=True,
            maintainer='{MAINTAINER}',
            maintainer_email='{MAINTAINER_EMAIL}',
            description='{description}',
            license='Apache-2.0',
            entry_points={{
                'console_scripts': [
        {{scripts}}
                ],
            }},
        )
        """).replace("{scripts}", scripts)


def setup_cfg(name: str) -> str:
    """setup.cfg: put console scripts in lib/NAME, where ``ros2 run`` looks for executables."""
    return (f"[develop]\nscript_dir=$base/lib/{name}\n"
            f"[install]\ninstall_scripts=$base/lib/{name}\n")


def interface_cmakelists(name: str, definitions: list[str], dependencies: list[str]) -> str:
    """CMakeLists.txt of an interface package: rosidl generates code for ``definitions``
    ('msg/BinLevel.msg', ...), which may use the interface packages ``dependencies``."""
    find = "".join(f"find_package({dep} REQUIRED)\n" for dep in dependencies)
    files = "\n".join(f'  "{item}"' for item in definitions)
    dep_line = f"\n  DEPENDENCIES {' '.join(dependencies)}" if dependencies else ""
    return ("cmake_minimum_required(VERSION 3.16)\n"
            f"project({name})\n\n"
            "find_package(ament_cmake REQUIRED)\n"
            "find_package(rosidl_default_generators REQUIRED)\n"
            f"{find}\n"
            "rosidl_generate_interfaces(${PROJECT_NAME}\n"
            f"{files}{dep_line}\n)\n\n"
            "ament_export_dependencies(rosidl_default_runtime)\n"
            "ament_package()\n")


def interface_package_xml(name: str, dependencies: list[str]) -> str:
    """package.xml of an interface package (ament_cmake, member of rosidl_interface_packages)."""
    depend_lines = "".join(f"  <depend>{dep}</depend>\n" for dep in dependencies)
    return ('<?xml version="1.0"?>\n<package format="3">\n'
            f"  <name>{name}</name>\n  <version>0.1.0</version>\n"
            f"  <description>Interfaces made in chapter 09</description>\n"
            f'  <maintainer email="{MAINTAINER_EMAIL}">{MAINTAINER}</maintainer>\n'
            "  <license>Apache-2.0</license>\n\n"
            "  <buildtool_depend>ament_cmake</buildtool_depend>\n"
            "  <buildtool_depend>rosidl_default_generators</buildtool_depend>\n"
            f"{depend_lines}"
            "  <exec_depend>rosidl_default_runtime</exec_depend>\n"
            "  <member_of_group>rosidl_interface_packages</member_of_group>\n\n"
            "  <export>\n    <build_type>ament_cmake</build_type>\n  </export>\n</package>\n")


def read_manifest(path: Path) -> dict:
    """Read a package.xml: ``{'name': ..., 'build_type': ..., 'depends': [...]}`` (CourseError if
    it does not parse)."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise CourseError(f"{path.name} is not valid XML: {exc}") from None
    depends = sorted({e.text.strip() for tag in ("depend", "exec_depend", "build_depend")
                      for e in root.iter(tag) if e.text})
    return {
        "name": (root.findtext("name") or "").strip(),
        "build_type": (root.findtext("export/build_type") or "").strip(),
        "depends": depends,
    }


def path_inside(base: Path, relative: str) -> Path:
    """``base / relative``, after checking that ``relative`` is a relative path that stays inside ``base``."""
    if not isinstance(relative, str) or not relative or Path(relative).is_absolute():
        raise CourseError(f"paths must be relative, like 'setup.py' or 'pkg/node.py'; got {relative!r}")
    path = (base / relative).resolve()
    if path != base.resolve() and base.resolve() not in path.parents:
        raise CourseError(f"path {relative!r} leaves the package directory")
    return path


def write_package_files(folder, files: dict[str, str]) -> Path:
    """Write ``files`` (relative path -> text) into ``folder``, making the folders they need; returns it.

    Files already there that ``files`` does not name are left as they are.
    """
    folder = Path(folder)
    for relative, text in files.items():
        path = path_inside(folder, relative)
        if not isinstance(text, str):
            raise CourseError(f"the content of {relative!r} must be a string, got {type(text).__name__}")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return folder


def read_package(folder) -> dict[str, str]:
    """The files under ``folder`` (a package's folder, as ``%%writefile`` cells wrote it): relative path
    with ``/`` -> text, sorted by path. Python's caches (``__pycache__``) and hidden files are left out.

    Raises :class:`CourseError` if ``folder`` is not a folder or holds a file that is not UTF-8 text.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise CourseError(f"{str(folder)!r} is not a folder: run the cells that write the package first")
    files = {}
    for path in sorted(folder.rglob("*")):
        relative = path.relative_to(folder)
        if not path.is_file() or "__pycache__" in relative.parts or any(
                part.startswith(".") for part in relative.parts):
            continue
        try:
            files[relative.as_posix()] = path.read_text(encoding="utf-8")
        except UnicodeDecodeError as error:
            raise CourseError(f"{relative.as_posix()} in {str(folder)!r} is not UTF-8 text: a package's "
                              "files are text") from error
    return files
