"""The package's folders are its layers: every import goes downward (or stays inside its own unit).

Layers, bottom to top: core < notebook < viz < nodes < chapters < checks | solutions.
A chapter package never imports another chapter; checkers never import the reference
solutions (a student build leaves them out). Function-level imports count too, and so do imports
by name at run time (``importlib.import_module``, ``__import__``) whose argument is a string the
module spells out (a literal, a module constant, ``__name__``, an f-string's constant start).

Each rule is a function that returns what breaks it; ``test_each_rule_fails_on_a_bad_example``
feeds every rule small bad modules and sees each one reported.
"""

from __future__ import annotations

import ast
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from .conftest import REPO

PACKAGE_NAME = "course_helpers"
PACKAGE = Path(REPO) / PACKAGE_NAME
RANK = {"core": 0, "notebook": 1, "viz": 2, "nodes": 3, "chapters": 4, "checks": 5, "solutions": 5}
ROOT_RANK = 6  # course_helpers/__init__.py: the entry point may use every layer
MAX_MODULE_LINES = 500

# --- what core/ may import besides the standard library: two named lists
# ROS 2's own Python packages, from the Jazzy wheels (rosgraph_msgs: the /clock message of sim_clock.py).
ROS_PACKAGES = {"rclpy", "rcl_interfaces", "rosidl_parser", "rosgraph_msgs"}
# A few other pinned libraries, each for one job and only in the modules named.
CORE_EXTRAS = {
    "yaml": ({"course_helpers.core.msg_yaml", "course_helpers.core.bags.writer",
              "course_helpers.core.bags.reader"},
             "messages as YAML, the way `ros2 topic echo` prints them; a bag's metadata.yaml, read and "
             "written in the key order Jazzy's rosbag2 uses"),
    "rosbags": ({"course_helpers.core.bags.qos", "course_helpers.core.bags.types",
                 "course_helpers.core.bags.writer", "course_helpers.core.bags.reader"},
                "rosbag2's storage formats (MCAP, SQLite 3) read and written in pure Python: the QoS "
                "records a bag keeps, message definitions and RIHS01 hashes, the writer and the reader"),
    "numpy": ({"course_helpers.core.build_interfaces"}, "the rosidl build needs NumPy's C headers"),
    "psutil": ({"course_helpers.core.domains", "course_helpers.core.supervisor",
                "course_helpers.core.processes", "course_helpers.core.other_kernels",
                "course_helpers.core.machine_load", "course_helpers.core.kernel_shutdown",
                "course_helpers.core.mapped_files"},
               "who holds a domain; the descendants a child ends when it exits; the program under a "
               "child's supervisor; the other kernels of the same Jupyter server; the machine's CPU "
               "time and this process tree's during a measurement; "
               "a kernel's id in its command line, and waiting until a shut-down kernel has ended; "
               "the files a process maps (its libraries, Fast DDS's shared memory)"),
    "IPython": ({"course_helpers.core.console"}, "a node's console under its notebook cell"),
    "jupyter_core": ({"course_helpers.core.kernel_shutdown"},
                     "Jupyter's runtime folder, where this kernel's server keeps its port and token"),
}

# --- imports by name at run time
# Upward on purpose: (importing module, imported module) -> why.
LOOKUPS_BY_NAME = {
    ("course_helpers.notebook.solution", "course_helpers.solutions"):
        "the solution button finds a reference solution by name when pressed; a student release "
        "leaves solutions/ out and the button says so (no code of the notebook layer depends on it)",
}
# Modules whose run-time imports name something the caller gives (no package module is spelled out).
IMPORTS_WHAT_IT_IS_GIVEN = {
    "course_helpers.core.child": "the target a kernel names for a child process ('module:callable')",
    "course_helpers.core.validation": "the ROS interface package named in a type ('std_msgs/msg/String')",
    "course_helpers.core.msg_yaml": "the message type a field of a message definition names",
    "course_helpers.checks.ch00_environment": "each dependency the environment check tries to import",
    "course_helpers.chapters.ch09_packages.interfaces": "the interface package the student just built",
}

# --- starting processes: only the process layer does it
PROCESS_LAYER = {"course_helpers.core.processes", "course_helpers.core.process_groups",
                 "course_helpers.core.supervisor"}
STARTER_MODULES = {"subprocess", "multiprocessing", "pty", "concurrent.futures.process"}
STARTER_NAMES = re.compile(
    r"^(subprocess|multiprocessing|concurrent\.futures\.process)(\..+)?$"
    r"|^os\.(system|popen|fork|forkpty|posix_spawnp?|exec\w*|spawn\w*)$"
    r"|^pty\.(fork|spawn)$"
    r"|^asyncio\.(create_subprocess_\w+|subprocess(\..+)?)$"
    r"|^concurrent\.futures\.ProcessPoolExecutor$"
    r"|^webbrowser\.(open\w*|get)$"
)
LOOP_STARTERS = {"subprocess_exec", "subprocess_shell"}  # asyncio event-loop methods, on any object

# --- scratch files: private to the process (processes.log_dir(), tempfile.mkdtemp/mkstemp)
SHARED_TEMP_CALLS = {"tempfile.gettempdir", "tempfile.gettempdirb", "tempfile.mktemp"}
SHARED_TEMP_PREFIXES = ("/tmp", "/var/tmp")  # (/dev/shm is Fast DDS's: the package only reads it)


@dataclass
class Module:
    path: Path
    name: str  # dotted, e.g. course_helpers.core.runtime

    @property
    def tree(self) -> ast.Module:
        return ast.parse(self.path.read_text(), str(self.path))

    @property
    def where(self) -> str:
        return str(self.path.relative_to(self.path.parents[len(self.name.split(".")) - 1]))


def _modules(root: Path = PACKAGE) -> list[Module]:
    found = []
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found.append(Module(path, ".".join(parts)))
    return found


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


def _package_of(module: Module) -> str:
    return module.name if module.path.name == "__init__.py" else module.name.rpartition(".")[0]


def _static_imports(module: Module):
    """(line, imported module) for every import statement, relative ones resolved."""
    for node in ast.walk(module.tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = _package_of(module).split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            yield node.lineno, target
            for alias in node.names:  # `from course_helpers.core import runtime` imports a module
                yield node.lineno, f"{target}.{alias.name}"


def _aliases(tree: ast.Module) -> dict[str, str]:
    """Local name -> what it stands for, from every import in the file (``sp`` -> ``subprocess``)."""
    names = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname:
                    names[alias.asname] = alias.name
                else:
                    top = alias.name.split(".")[0]
                    names[top] = top
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            for alias in node.names:
                names[alias.asname or alias.name] = f"{node.module}.{alias.name}"
    return names


def _dotted(node: ast.AST, aliases: dict[str, str]) -> str | None:
    """``os.fork`` for the expression ``os.fork`` (names resolved through the imports), else None."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return None
    return ".".join([aliases.get(node.id, node.id), *reversed(parts)])


def _string_constants(module: Module, tree: ast.Module) -> dict[str, str]:
    """Module-level ``NAME = 'text'`` assignments, plus ``__name__`` and ``__package__``."""
    constants = {"__name__": module.name, "__package__": _package_of(module)}
    for node in tree.body:
        if (isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name)
                and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str)):
            constants[node.targets[0].id] = node.value.value
    return constants


def _spelled(node: ast.AST, constants: dict[str, str]) -> tuple[str, bool]:
    """The text a string expression starts with that the module spells out, and whether that is all of it."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value, True
    if isinstance(node, ast.Name) and node.id in constants:
        return constants[node.id], True
    if isinstance(node, ast.JoinedStr):
        text = ""
        for part in node.values:
            if isinstance(part, ast.Constant):
                text += str(part.value)
                continue
            if (isinstance(part, ast.FormattedValue) and part.conversion == -1 and part.format_spec is None
                    and isinstance(part.value, ast.Name) and part.value.id in constants):
                text += constants[part.value.id]
                continue
            return text, False
        return text, True
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
        left, whole = _spelled(node.left, constants)
        if not whole:
            return left, False
        right, whole = _spelled(node.right, constants)
        return left + right, whole
    return "", False


def _dynamic_imports(module: Module):
    """(line, imported module or None) for each ``import_module``/``__import__`` call.

    The module is what the argument spells out (up to its last dot when only a start is spelled
    out); None when nothing of it is.
    """
    tree = module.tree
    aliases, constants = _aliases(tree), _string_constants(module, tree)
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call) or not node.args:
            continue
        called = _dotted(node.func, aliases)
        if called not in ("importlib.import_module", "__import__", "importlib.__import__"):
            continue
        text, whole = _spelled(node.args[0], constants)
        if not whole:
            text = text.rpartition(".")[0] if "." in text else ""
        if text.startswith("."):  # relative to this module's package
            level = len(text) - len(text.lstrip("."))
            base = _package_of(module).split(".")
            text = ".".join(base[: len(base) - level + 1] + ([text.lstrip(".")] if text.lstrip(".") else []))
        yield node.lineno, text or None


def _is_module(name: str) -> bool:
    path = Path(REPO, *name.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


# ---------------------------------------------------------------------- the rules
def imports_that_go_up_or_sideways(modules: list[Module]) -> list[str]:
    wrong = []
    for module in modules:
        rank, unit = _unit(module.name)
        found = [(line, target, "imports") for line, target in _static_imports(module)]
        found += [(line, target, "imports by name") for line, target in _dynamic_imports(module) if target]
        for line, target, how in found:
            if not target.startswith(PACKAGE_NAME) or not _is_module(target):
                continue
            target_rank, target_unit = _unit(target)
            if target_unit == unit or target_rank < rank:
                continue
            if how == "imports by name" and (module.name, target) in LOOKUPS_BY_NAME:
                continue
            wrong.append(f"{module.where}:{line} {how} {target} ({target_unit} is not below {unit})")
    return sorted(set(wrong))


def imports_by_name_nobody_can_read(modules: list[Module]) -> list[str]:
    """Run-time imports whose argument spells out no module, outside the modules named for it."""
    return [f"{module.where}:{line} imports a module by a name it does not spell out"
            for module in modules for line, target in _dynamic_imports(module)
            if target is None and module.name not in IMPORTS_WHAT_IT_IS_GIVEN]


def core_imports_outside_its_lists(modules: list[Module]) -> list[str]:
    wrong = []
    for module in modules:
        if _unit(module.name)[1] != "core":
            continue
        for line, target in _static_imports(module):
            top = target.split(".")[0]
            if top in (PACKAGE_NAME, "", "__future__") or top in sys.stdlib_module_names:
                continue
            if top in ROS_PACKAGES:
                continue
            if top in CORE_EXTRAS and module.name in CORE_EXTRAS[top][0]:
                continue
            wrong.append(f"{module.where}:{line} imports {target}")
    return wrong


def process_starts_outside_the_process_layer(modules: list[Module]) -> list[str]:
    found = []
    for module in modules:
        if module.name in PROCESS_LAYER:
            continue
        tree = module.tree
        aliases = _aliases(tree)
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                found += [f"{module.where}:{node.lineno} imports {a.name}" for a in node.names
                          if a.name in STARTER_MODULES or STARTER_NAMES.match(a.name)]
            elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
                found += [f"{module.where}:{node.lineno} imports {node.module}.{a.name}" for a in node.names
                          if node.module in STARTER_MODULES or STARTER_NAMES.match(f"{node.module}.{a.name}")]
            elif isinstance(node, (ast.Attribute, ast.Name)) and isinstance(node.ctx, ast.Load):
                name = _dotted(node, aliases)
                if name and STARTER_NAMES.match(name):
                    found.append(f"{module.where}:{node.lineno} uses {name}")
                elif isinstance(node, ast.Attribute) and node.attr in LOOP_STARTERS:
                    found.append(f"{module.where}:{node.lineno} uses .{node.attr}")
    return sorted(set(found))


def predictable_shared_paths(modules: list[Module]) -> list[str]:
    """Paths in a folder every user shares, by a name another user can guess and create first."""
    found = []
    for module in modules:
        tree = module.tree
        aliases = _aliases(tree)
        for node in ast.walk(tree):
            if isinstance(node, (ast.Attribute, ast.Name)) and isinstance(node.ctx, ast.Load):
                if _dotted(node, aliases) in SHARED_TEMP_CALLS:
                    found.append(f"{module.where}:{node.lineno} uses {_dotted(node, aliases)}")
            elif isinstance(node, ast.Constant) and isinstance(node.value, str) and any(
                    node.value == p or node.value.startswith(p + "/") for p in SHARED_TEMP_PREFIXES):
                found.append(f"{module.where}:{node.lineno} names {node.value}")
    return sorted(set(found))


def modules_too_long(modules: list[Module]) -> list[str]:
    return [f"{module.where} has {n} lines; split it by job (the limit is {MAX_MODULE_LINES})"
            for module in modules if (n := len(module.path.read_text().splitlines())) > MAX_MODULE_LINES]


# ---------------------------------------------------------------------- the package keeps them
def test_every_import_goes_down_a_layer():
    wrong = imports_that_go_up_or_sideways(_modules())
    assert not wrong, "imports that go up or sideways:\n" + "\n".join(wrong)


def test_every_import_by_name_spells_out_its_module_or_is_named_here():
    wrong = imports_by_name_nobody_can_read(_modules())
    assert not wrong, ("spell the module out (a literal, a module constant, an f-string's start), or name "
                       "the module in IMPORTS_WHAT_IT_IS_GIVEN with why:\n" + "\n".join(wrong))


def test_core_needs_only_the_standard_library_ros_and_its_named_extras():
    wrong = core_imports_outside_its_lists(_modules())
    assert not wrong, ("core/ imports outside the standard library, ROS_PACKAGES and CORE_EXTRAS (each "
                       "extra for its named modules only):\n" + "\n".join(wrong))


def test_only_the_process_layer_starts_processes():
    starters = process_starts_outside_the_process_layer(_modules())
    assert not starters, "start child processes with course_helpers.core.processes:\n" + "\n".join(starters)


def test_scratch_files_are_private_to_the_process():
    shared = predictable_shared_paths(_modules())
    assert not shared, ("write scratch files into processes.log_dir() or a tempfile.mkdtemp() folder, never "
                        "by a name in a shared folder:\n" + "\n".join(shared))


@pytest.mark.parametrize("module", _modules(), ids=lambda m: str(m.path.relative_to(PACKAGE)))
def test_modules_stay_small(module):
    assert not modules_too_long([module]), modules_too_long([module])[0]


def test_every_named_exception_is_still_needed():
    """An exception that no module uses any more is removed, so the lists say only what is true."""
    modules = _modules()
    by_name = {m.name: m for m in modules}
    lookups = {(m.name, t) for m in modules for _, t in _dynamic_imports(m)}
    assert set(LOOKUPS_BY_NAME) <= lookups, set(LOOKUPS_BY_NAME) - lookups
    unread = {m.name for m in modules for _, t in _dynamic_imports(m) if t is None}
    assert set(IMPORTS_WHAT_IT_IS_GIVEN) <= unread, set(IMPORTS_WHAT_IT_IS_GIVEN) - unread
    for extra, (users, _why) in CORE_EXTRAS.items():
        for user in users:
            tops = {t.split(".")[0] for _, t in _static_imports(by_name[user])}
            assert extra in tops, f"CORE_EXTRAS allows {extra} in {user}, which no longer imports it"
    used = {t.split(".")[0] for m in modules if _unit(m.name)[1] == "core" for _, t in _static_imports(m)}
    assert ROS_PACKAGES <= used, ROS_PACKAGES - used
    assert PROCESS_LAYER <= set(by_name)


# ---------------------------------------------------------------------- the rules can fail
BAD_EXAMPLES = {
    imports_that_go_up_or_sideways: {
        "core/upward.py": "def f():\n    from course_helpers.chapters.ch07_dds import dds\n",
        "chapters/ch03_topics.py": "from course_helpers.chapters import ch04_services\n",
        "checks/peeks.py": "from course_helpers.solutions import ch03_topics\n",
        "notebook/by_fstring.py": ("import importlib\nPKG = 'course_helpers.chapters'\n"
                                   "def f(name):\n    return importlib.import_module(f'{PKG}.{name}')\n"),
        "viz/by_dunder.py": "X = __import__('course_helpers.checks.ch03_topics')\n",
        "core/by_concat.py": ("from importlib import import_module as load\n"
                              "def f(n):\n    return load('course_helpers.nodes.' + n)\n"),
    },
    imports_by_name_nobody_can_read: {
        "core/unreadable.py": "import importlib\ndef f(name):\n    return importlib.import_module(name)\n",
    },
    core_imports_outside_its_lists: {
        "core/web.py": "import requests\n",
        "core/yaml_elsewhere.py": "def f():\n    import yaml\n",
    },
    process_starts_outside_the_process_layer: {
        "core/a.py": "import subprocess\n",
        "core/b.py": "import subprocess as sp\n",
        "core/c.py": "from os import posix_spawn\n",
        "core/d.py": "import os\ndef f():\n    os.posix_spawnp('ls', ['ls'], {})\n",
        "core/e.py": "import os\nos.execvp('ls', ['ls'])\n",
        "core/f.py": "import os\nstart = os.fork\n",
        "core/g.py": "import os\nos.system('ls')\n",
        "core/h.py": "import os as o\no.spawnlp(o.P_WAIT, 'ls', 'ls')\n",
        "core/i.py": "import pty\n",
        "core/j.py": "import asyncio\nasync def f():\n    await asyncio.create_subprocess_exec('ls')\n",
        "core/k.py": "async def f(loop):\n    await loop.subprocess_shell(lambda: None, 'ls')\n",
        "core/l.py": "import multiprocessing\n",
        "core/m.py": "from concurrent.futures import ProcessPoolExecutor\n",
        "core/n.py": "import os\nos.forkpty()\n",
        "core/o.py": "import os\nos.popen('ls')\n",
    },
    predictable_shared_paths: {
        "chapters/ch01_architecture.py": ("import os, tempfile\n"
                                          "path = os.path.join(tempfile.gettempdir(), 'lease.xml')\n"),
        "core/fixed.py": "PATH = '/tmp/ros2-course-domains'\n",
        "core/racy.py": "from tempfile import mktemp\nname = mktemp()\n",
    },
    modules_too_long: {
        "core/long.py": "x = 1\n" * (MAX_MODULE_LINES + 1),
    },
}


@pytest.mark.parametrize("rule, relative",
                         [(rule, relative) for rule, cases in BAD_EXAMPLES.items() for relative in cases],
                         ids=lambda v: v.__name__ if callable(v) else v)
def test_each_rule_fails_on_a_bad_example(tmp_path, rule, relative):
    path = tmp_path / PACKAGE_NAME / relative
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(BAD_EXAMPLES[rule][relative])
    modules = [m for m in _modules(tmp_path / PACKAGE_NAME) if m.path == path]
    assert len(modules) == 1
    assert rule(modules), f"{rule.__name__} did not report {relative}:\n{path.read_text()}"


def test_the_rules_pass_good_examples(tmp_path):
    """Downward imports, a spelled-out import by name inside its unit, and plain os calls are fine."""
    good = {
        "chapters/ch03_topics.py": ("import importlib, os\nfrom course_helpers.core import processes\n"
                                    "def f(n):\n    os.getpid()\n"
                                    "    return importlib.import_module(f'{__name__}.{n}')\n"),
        "core/tidy.py": "import json\nimport rclpy\nimport os.path\n",
    }
    for relative, text in good.items():
        path = tmp_path / PACKAGE_NAME / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    modules = _modules(tmp_path / PACKAGE_NAME)
    for rule in BAD_EXAMPLES:
        assert not rule(modules), (rule.__name__, rule(modules))
