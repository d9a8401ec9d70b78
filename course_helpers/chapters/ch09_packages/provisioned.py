"""A package run where only what its package.xml declares is installed, as on a robot set up from it.

A robot is set up for a package with ``rosdep install --from-paths src``: rosdep reads the package's
``package.xml`` and installs the ROS packages it names, and theirs, and nothing else. On such a robot
a node that imports a ROS package its manifest forgot fails at its first line, even though it ran on
the developer's machine, where everything happened to be installed. :func:`provision` builds that
robot's Python from this machine's ROS installation: the package's run dependencies (what the ROS
build farm makes the dependencies of its binary package: ``depend``, ``exec_depend``,
``build_export_depend``, ``buildtool_export_depend`` and format 1's ``run_depend``) are followed
through the installed packages' own ``package.xml`` files, and every ROS package outside that
closure is left out of the directory the node imports from.

Only ROS packages (those in the ament index of this venv) are left out. Other keys of a manifest
(``python3-yaml``) are rosdep's system dependencies, installed by the operating system's package
manager; every Python library of the venv that is not a ROS package stays importable. The node runs
with this venv's interpreter started with ``-S`` (no site directory, so nothing reaches it through
the venv's site-packages or its ``.pth`` files) and ``PYTHONPATH`` = the workspace's own install
directories, then the provisioned directory.
"""

from __future__ import annotations

import os
import shutil
import sys
import sysconfig
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

from course_helpers.core.errors import CourseError

# the tags of package.xml whose packages a binary package needs at run time (ros_buildfarm's run
# dependencies: build_export_depends + buildtool_export_depends + exec_depends; format 2's <depend>
# is all three, format 1's <run_depend> the first and the last)
RUN_DEPENDENCY_TAGS = ("depend", "exec_depend", "run_depend", "build_export_depend",
                       "buildtool_export_depend")
PYTHON_FLAGS = ("-S",)  # the interpreter's own site directory stays out


@dataclass
class Provisioned:
    """What :func:`provision` set up: the ROS packages installed there and how to run a node there."""

    package: str
    declared: list[str]  # the ROS packages the package's manifest names as run dependencies
    installed: list[str]  # every ROS package there: the declared ones and what they need
    left_out: list[str]  # this machine's ROS packages that are not there
    site: Path  # the directory the node imports from
    env: dict[str, str] = field(repr=False, default_factory=dict)

    def command(self, executable: Path) -> list[str]:
        """The command line that runs the console script ``executable`` there."""
        return [sys.executable, *PYTHON_FLAGS, str(executable)]

    def describe(self) -> str:
        """'rclpy, std_msgs and what they need (77 ROS packages)'."""
        if not self.declared:
            return "no ROS package"
        need = "what they need" if len(self.declared) > 1 else "what it needs"
        return f"{', '.join(self.declared)} and {need} ({len(self.installed)} ROS packages)"


def run_dependencies(manifest: Path) -> list[str]:
    """The packages (or rosdep keys) a package.xml names as run dependencies, sorted; CourseError if
    it does not parse."""
    try:
        root = ET.parse(manifest).getroot()
    except (ET.ParseError, OSError) as exc:
        raise CourseError(f"{manifest} is not a readable package.xml: {exc}") from None
    return sorted({e.text.strip() for tag in RUN_DEPENDENCY_TAGS for e in root.iter(tag)
                   if e.text and e.text.strip()})


def installed_ros_packages(prefixes: list[Path]) -> dict[str, Path]:
    """package name -> its package.xml, for every package in the ament index of ``prefixes`` (the first
    prefix that has a package wins, as on AMENT_PREFIX_PATH)."""
    found: dict[str, Path] = {}
    for prefix in prefixes:
        index = prefix / "share" / "ament_index" / "resource_index" / "packages"
        for marker in sorted(index.glob("*")) if index.is_dir() else []:
            manifest = prefix / "share" / marker.name / "package.xml"
            if marker.name not in found and manifest.is_file():
                found[marker.name] = manifest
    return found


def dependency_closure(roots, manifests: dict[str, Path]) -> set[str]:
    """The ROS packages of ``manifests`` that ``roots`` need at run time, ``roots`` included, following
    each one's own run dependencies; keys that are no installed ROS package are rosdep's system
    dependencies and are not followed."""
    needed: set[str] = set()
    waiting = [name for name in roots if name in manifests]
    while waiting:
        name = waiting.pop()
        if name in needed:
            continue
        needed.add(name)
        waiting += [dep for dep in run_dependencies(manifests[name]) if dep in manifests]
    return needed


def provision(package: str, manifest: Path, install_base: Path, env: dict[str, str],
              site: Path) -> Provisioned:
    """Set up ``site`` (made anew) so that a node of ``package`` (its source ``manifest``, what
    ``rosdep install --from-paths src`` reads; installed in the colcon install base ``install_base``)
    finds only the ROS packages the manifest declares and theirs. ``env`` is the workspace's
    environment (``source install/setup.bash``). Returns the :class:`Provisioned` whose ``env`` and
    ``command()`` run the node there."""
    ros = installed_ros_packages([Path(sys.prefix)])
    declared = [dep for dep in run_dependencies(manifest) if dep in ros]
    installed = dependency_closure(declared, ros)
    venv_site = Path(sysconfig.get_paths()["purelib"])
    if site.exists():
        shutil.rmtree(site)
    site.mkdir(parents=True)
    for entry in sorted(venv_site.iterdir()):
        if entry.name in ros and entry.name not in installed:
            continue  # a ROS package the manifest does not bring: not installed on this robot
        (site / entry.name).symlink_to(entry)
    own_paths = [p for p in env.get("PYTHONPATH", "").split(os.pathsep)
                 if p and Path(p).is_relative_to(install_base)]
    provisioned_env = {**env, "PYTHONPATH": os.pathsep.join([*own_paths, str(site)])}
    return Provisioned(package, declared, sorted(installed), sorted(set(ros) - installed), site,
                       provisioned_env)
