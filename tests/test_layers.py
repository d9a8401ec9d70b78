"""The package's folders are its layers: every import goes downward (or stays inside its own unit).

Layers, bottom to top: core < notebook < viz < nodes < chapters < checks | solutions.
A chapter package never imports another chapter; checkers never import the reference
solutions (a student build leaves them out). Function-level imports count too.
"""

from __future__ import annotations

import ast
import os
import sys
from pathlib import Path

import pytest

from .conftest import REPO

PACKAGE = Path(REPO) / "course_helpers"
RANK = {"core": 0, "notebook": 1, "viz": 2, "nodes": 3, "chapters": 4, "checks": 5, "solutions": 5}
ROOT_RANK = 6  # course_helpers/__init__.py: the entry point may use every layer
MAX_MODULE_LINES = 500
# What the bottom layer may import besides the standard library: rclpy and the ROS packages it
# needs (rosidl_parser, to read message definitions), PyYAML and NumPy (dependencies of rclpy
# and of the rosidl build), psutil (pinned: processes and sockets without parsing /proc by hand),
# and the Jupyter display libraries for node consoles.
CORE_THIRD_PARTY = {"rclpy", "rcl_interfaces", "builtin_interfaces", "rosidl_parser", "yaml", "numpy",
                    "psutil", "ipywidgets", "IPython"}


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        yield path, ".".join(parts)


def _unit(module: str) -> tuple[int, str]:
    """(rank, unit) of a course_helpers module: a chapter package is a unit of its own."""
    parts = module.split(".")
    if len(parts) == 1:
        return ROOT_RANK, "root"
    layer = parts[1]
    if layer not in RANK:
        raise AssertionError(f"{module}: every module must live in a layer folder {sorted(RANK)}")
    if layer == "chapters" and len(parts) > 2:
        return RANK[layer], f"chapters.{parts[2]}"
    return RANK[layer], layer


def _imports(path: Path, module: str):
    """(line, imported module) for every import in the file, relative ones resolved."""
    tree = ast.parse(path.read_text(), str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            yield node.lineno, target
            for alias in node.names:  # `from course_helpers.core import runtime` imports a module
                yield node.lineno, f"{target}.{alias.name}"


def _is_module(name: str) -> bool:
    path = Path(REPO, *name.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def test_every_import_goes_down_a_layer():
    wrong = []
    for path, module in _modules():
        rank, unit = _unit(module)
        for line, target in _imports(path, module):
            if not target.startswith("course_helpers") or not _is_module(target):
                continue
            target_rank, target_unit = _unit(target)
            if target_unit != unit and target_rank >= rank:
                wrong.append(f"{path.relative_to(REPO)}:{line} imports {target} "
                             f"({target_unit} is not below {unit})")
    assert not wrong, "imports that go up or sideways:\n" + "\n".join(sorted(set(wrong)))


def test_core_needs_only_rclpy_and_the_standard_library():
    wrong = []
    for path, module in _modules():
        if _unit(module)[1] != "core":
            continue
        for line, target in _imports(path, module):
            top = target.split(".")[0]
            if top in ("course_helpers", "") or top in sys.stdlib_module_names or top in CORE_THIRD_PARTY:
                continue
            wrong.append(f"{path.relative_to(REPO)}:{line} imports {target}")
    assert not wrong, "core/ imports outside rclpy and the standard library:\n" + "\n".join(wrong)


def test_only_the_process_layer_starts_processes():
    starters = []
    for path, module in _modules():
        if module == "course_helpers.core.processes":
            continue
        for line, target in _imports(path, module):
            if target.split(".")[0] in ("subprocess", "multiprocessing") or target in ("os.system",):
                starters.append(f"{path.relative_to(REPO)}:{line} imports {target}")
        text = path.read_text()
        for call in ("os.fork(", "os.spawn", "os.system(", "os.popen("):
            if call in text:
                starters.append(f"{path.relative_to(REPO)} calls {call}")
    assert not starters, "start child processes with course_helpers.core.processes:\n" + "\n".join(starters)


@pytest.mark.parametrize("path", [p for p, _ in _modules()], ids=lambda p: str(p.relative_to(PACKAGE)))
def test_modules_stay_small(path):
    lines = len(path.read_text().splitlines())
    assert lines <= MAX_MODULE_LINES, (
        f"{path.relative_to(REPO)} has {lines} lines; split it by job (the limit is {MAX_MODULE_LINES})")


def test_the_layer_test_sees_an_upward_import(tmp_path):
    """The checker itself works: a core module importing a chapter is reported."""
    fake = tmp_path / "probe.py"
    fake.write_text("def f():\n    from course_helpers.chapters.ch07_dds import dds\n")
    found = [target for _, target in _imports(fake, "course_helpers.core.probe")]
    assert "course_helpers.chapters.ch07_dds" in found
    assert _unit("course_helpers.chapters.ch07_dds")[0] > _unit("course_helpers.core.probe")[0]
    assert os.path.isdir(PACKAGE / "core")
