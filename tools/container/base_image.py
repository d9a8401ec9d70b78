"""The Dockerfile's base image, ``debian:bookworm-slim``, present in the engine's local storage.

If the engine already has it, nothing happens. Otherwise it is pulled from the registry; where no
image registry can be reached but Debian's package mirror can (a machine behind a package proxy,
a CI runner), it is made locally: ``debootstrap --variant=minbase bookworm`` from the Debian mirror
that this machine's apt uses (read from ``apt-cache policy`` at run time), trimmed as Debian's
official slim image is (no manuals, documentation or translations; the copyright files stay), and
imported under the public name. The Dockerfile's ``FROM`` is then the same on every machine.
Making it needs root and debootstrap (``apt-get install debootstrap``); about 2.5 minutes.

    python -m tools.container.base_image      # from the repository root: make sure the base is there
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tools.container.engine import Engine, EngineError, find_engine

BASE_IMAGE = "docker.io/library/debian:bookworm-slim"  # what `FROM debian:bookworm-slim` names
SUITE = "bookworm"
# What Debian's slim images leave out, kept out of later `apt-get install`s too (dpkg path filters).
SLIM_DPKG_FILTERS = """\
path-exclude /usr/share/doc/*
path-include /usr/share/doc/*/copyright
path-exclude /usr/share/man/*
path-exclude /usr/share/groff/*
path-exclude /usr/share/info/*
path-exclude /usr/share/lintian/*
path-exclude /usr/share/linda/*
path-exclude /usr/share/locale/*
path-include /usr/share/locale/locale.alias
"""
SLIM_REMOVED = ("usr/share/man", "usr/share/groff", "usr/share/info", "usr/share/lintian",
                "usr/share/linda", "var/cache/apt/archives", "var/lib/apt/lists")


def debian_mirror(policy: str | None = None) -> str:
    """The Debian mirror apt uses for the ``bookworm`` suite's main component.

    ``policy`` is the output of ``apt-cache policy`` (read from this machine when not given).
    """
    if policy is None:
        try:
            policy = subprocess.run(["apt-cache", "policy"], capture_output=True, text=True,
                                    timeout=60).stdout
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise EngineError(f"cannot read apt's sources (apt-cache policy): {exc}") from exc
    # e.g. " 500 http://deb.debian.org/debian bookworm/main amd64 Packages"
    match = re.search(rf"^\s*\d+\s+(\S+)\s+{SUITE}/main\s", policy, re.MULTILINE)
    if not match:
        raise EngineError(f"apt on this machine has no source for Debian {SUITE}/main "
                          "(apt-cache policy lists none), so the base image cannot be made here")
    return match.group(1)


def _slim(root: Path) -> None:
    (root / "etc/dpkg/dpkg.cfg.d").mkdir(parents=True, exist_ok=True)
    (root / "etc/dpkg/dpkg.cfg.d/slim").write_text(SLIM_DPKG_FILTERS)
    for relative in SLIM_REMOVED:
        for entry in (root / relative).glob("*"):
            if entry.name in ("lock", "partial"):  # apt's own
                continue
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
    for doc in (root / "usr/share/doc").glob("*"):
        for entry in doc.iterdir() if doc.is_dir() and not doc.is_symlink() else ():
            if entry.name != "copyright":
                shutil.rmtree(entry) if entry.is_dir() and not entry.is_symlink() else entry.unlink()
    locale = root / "usr/share/locale"
    for entry in locale.glob("*"):
        if entry.name != "locale.alias":
            shutil.rmtree(entry) if entry.is_dir() else entry.unlink()


def make_locally(engine: Engine, echo=print) -> None:
    """Bootstrap Debian into a temporary directory and import it as BASE_IMAGE."""
    if shutil.which("debootstrap") is None:
        raise EngineError(f"{BASE_IMAGE} is not in the local storage, cannot be pulled, and debootstrap "
                          "is missing to make it (apt-get install debootstrap)")
    mirror = debian_mirror()
    with tempfile.TemporaryDirectory(prefix="course-base-", dir="/var/tmp") as scratch:
        root = Path(scratch) / "rootfs"
        echo(f"making {BASE_IMAGE}: debootstrap --variant=minbase {SUITE} from {mirror}")
        done = subprocess.run(["debootstrap", "--variant=minbase", SUITE, str(root), mirror],
                              capture_output=True, text=True, timeout=1800)
        if done.returncode != 0:
            log = root / "debootstrap/debootstrap.log"
            detail = log.read_text()[-3000:] if log.exists() else done.stderr[-3000:]
            raise EngineError(f"debootstrap failed ({done.returncode}):\n{detail}")
        _slim(root)
        tar = subprocess.Popen(["tar", "-C", str(root), "--numeric-owner", "-c", "."], stdout=subprocess.PIPE)
        imported = subprocess.run(engine.command("import", "--change", 'CMD ["bash"]', "-", BASE_IMAGE),
                                  stdin=tar.stdout, capture_output=True, text=True, timeout=1800)
        tar.stdout.close()
        if tar.wait() != 0 or imported.returncode != 0:
            raise EngineError(f"importing the bootstrapped system failed:\n{imported.stderr[-3000:]}")


def ensure_base_image(engine: Engine, echo=print) -> float:
    """Make sure BASE_IMAGE is in the engine's storage; return the seconds it took (0 if present)."""
    if engine.has_image(BASE_IMAGE):
        echo(f"{BASE_IMAGE} is in the local storage")
        return 0.0
    started = time.monotonic()
    pulled = engine.call("pull", BASE_IMAGE, timeout=900)
    if pulled.returncode == 0:
        echo(f"pulled {BASE_IMAGE}")
    else:
        reason = (pulled.stderr.strip().splitlines() or ["no output"])[-1]
        echo(f"cannot pull {BASE_IMAGE} ({reason}); making it locally instead")
        make_locally(engine, echo)
    return time.monotonic() - started


if __name__ == "__main__":
    try:
        seconds = ensure_base_image(find_engine())
    except EngineError as error:
        sys.exit(f"error: {error}")
    print(f"base image ready ({seconds:.0f} s)")
