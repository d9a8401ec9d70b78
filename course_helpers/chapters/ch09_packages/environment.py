"""What ``source install/setup.bash`` does, computed from the ``.dsv`` hook files colcon installs.

colcon installs, for each package, ``share/PKG/package.dsv`` listing hooks such as
``prepend-non-duplicate;PYTHONPATH;lib/python3.X/site-packages``; the shell scripts do
exactly what these lines say. :func:`workspace_environment` applies them to a copy of an
environment instead of a shell. Also the changes this kernel makes to its own search
paths when it loads a freshly built package (:func:`prepend_env`, :func:`forget_env_entries_under`).
"""

from __future__ import annotations

import os
import re
from pathlib import Path


def installed_packages(install_base: Path) -> list[str]:
    """The packages in ``install_base``, in the order colcon's setup script would add them
    (dependencies first)."""
    index = {}
    for marker in sorted(install_base.glob("*/share/colcon-core/packages/*")):
        index[marker.name] = [d for d in marker.read_text().split(":") if d]
    ordered: list[str] = []

    def visit(name, seen=()):
        if name in ordered or name not in index or name in seen:
            return
        for dep in index[name]:
            visit(dep, (*seen, name))
        ordered.append(name)

    for name in sorted(index):
        visit(name)
    return ordered


def workspace_environment(install_base: Path, base: dict[str, str] | None = None) -> dict[str, str]:
    """The environment sourcing ``install_base/setup.bash`` would give: a copy of ``base``
    (default: this process's environment) with every installed package's hooks applied."""
    env = dict(os.environ if base is None else base)
    for package in installed_packages(install_base):
        prefix = install_base / package
        apply_dsv(prefix / "share" / package / "package.dsv", prefix, env)
    return env


def apply_dsv(path: Path, prefix: Path, env: dict[str, str]) -> None:
    """Apply one colcon .dsv hook file of the package installed at ``prefix`` to ``env`` (in place)."""
    if not path.is_file():
        return
    for line in path.read_text().splitlines():
        kind, _, rest = line.partition(";")
        if kind == "source":
            if rest.endswith(".dsv"):
                apply_dsv(prefix / rest, prefix, env)
            continue  # the .sh/.bash twins of a .dsv do the same thing for a shell
        name, _, values = rest.partition(";")
        entries = [str(prefix / v) if v else str(prefix) for v in values.split(";")]
        current = [p for p in env.get(name, "").split(os.pathsep) if p]
        if kind in ("prepend-non-duplicate", "prepend-non-duplicate-if-exists"):
            if kind.endswith("if-exists"):
                entries = [e for e in entries if os.path.exists(e)]
            env[name] = os.pathsep.join([*entries, *[p for p in current if p not in entries]])
        elif kind == "append-non-duplicate":
            env[name] = os.pathsep.join([*current, *[e for e in entries if e not in current]])
        elif kind == "set":
            env[name] = entries[0] if values else ""
        elif kind == "set-if-unset":
            env.setdefault(name, entries[0] if values else "")


def stable_name(name: str) -> str:
    """``name`` with the Python version hidden (python3.11 -> python3.X, py3.11 -> py3.X), for
    outputs that stay the same on every machine."""
    return re.sub(r"(python|py)3\.\d+", r"\g<1>3.X", name)


def prepend_env(name: str, entry: str) -> None:
    """Put ``entry`` first on this process's search path variable ``name`` (once)."""
    current = [p for p in os.environ.get(name, "").split(os.pathsep) if p and p != entry]
    os.environ[name] = os.pathsep.join([entry, *current])


def forget_env_entries_under(root: Path) -> None:
    """Drop the paths under ``root`` (a deleted workspace) from this process's search paths."""
    for name in ("AMENT_PREFIX_PATH", "LD_LIBRARY_PATH"):
        kept = [p for p in os.environ.get(name, "").split(os.pathsep)
                if p and not p.startswith(str(root))]
        if kept:
            os.environ[name] = os.pathsep.join(kept)
        else:
            os.environ.pop(name, None)
