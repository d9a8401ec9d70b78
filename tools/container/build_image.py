"""Build the course's image from the Dockerfile at the repository root (``make image``).

With Docker or Podman, whichever works here (engine.py). The base image is made first when the
engine does not have it (base_image.py). Each build step is timed as the engine's output streams
by, and the report (engine, image, size, the base's and each step's seconds) is printed and written
as JSON (``--report``, default ``build/image/build.json``).

When this machine's pip is set to trust its own certificate authority (``cert`` in the host's pip
configuration, or ``PIP_CERT``), pip inside the build needs it too: Podman then mounts that bundle
and a pip configuration naming it into the build's RUN steps, read-only, and neither ends up in
the image (see BUILD_HOME). Nothing of this machine is written into the repository.

    python -m tools.container.build_image [--tag ros2-course] [--no-cache]   # from the repository root
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tools.container.base_image import BASE_IMAGE, ensure_base_image
from tools.container.engine import Engine, EngineError, find_engine

REPO = Path(__file__).resolve().parents[2]
DEFAULT_TAG = "ros2-course"
DEFAULT_REPORT = REPO / "build" / "image" / "build.json"
# Where the host's CA bundle and the derived pip configuration appear inside RUN steps: a
# directory mounted over root's home, where pip (run as root) looks for its user configuration.
# A mount target that does not exist in the image would be left behind in it as an empty file;
# /root exists, so nothing is.
BUILD_HOME = "/root"
PIP_DIR = ".config/pip"
# Host pip settings that concern reaching the index; paths and local indexes stay behind.
NETWORK_KEYS = ("index-url", "extra-index-url", "trusted-host", "proxy", "timeout", "default-timeout",
                "retries")
# The build steps worth naming in the summary, found by what they run.
STAGES = (("system packages", "apt-get install"), ("pinned stack (pip)", "pip install"),
          ("make setup", "make setup"), ("working copy", "working_copy.py"))


def host_pip_settings(python: str = sys.executable) -> dict[str, str]:
    """The host pip's settings (``pip config list``; PIP_* variables win), keyed without scope."""
    settings: dict[str, str] = {}
    try:
        listed = subprocess.run([python, "-m", "pip", "config", "list"], capture_output=True, text=True,
                                timeout=60).stdout
    except (OSError, subprocess.TimeoutExpired):
        listed = ""
    for line in listed.splitlines():  # e.g. global.cert='/etc/ssl/certs/ca-certificates.crt'
        match = re.match(r"^[^.]*\.([\w-]+)='(.*)'$", line)
        if match:
            settings[match.group(1)] = match.group(2)
    for name, value in os.environ.items():
        if name.startswith("PIP_") and value:
            settings[name[4:].lower().replace("_", "-")] = value
    return settings


def pip_mounts(workdir: Path, settings: dict[str, str]) -> list[str]:
    """``-v`` options giving RUN steps the host's CA bundle and pip configuration, or [] if not needed."""
    cert = settings.get("cert")
    if not cert or not Path(cert).is_file():
        return []
    home = workdir / "home"
    (home / PIP_DIR).mkdir(parents=True)
    shutil.copyfile(cert, home / PIP_DIR / "host-ca.pem")
    lines = ["[global]", f"cert = {BUILD_HOME}/{PIP_DIR}/host-ca.pem"]
    for key in NETWORK_KEYS:
        values = [v for v in settings.get(key, "").split() if not v.startswith("file:")]
        if values:
            lines.append(f"{key} = {' '.join(values)}")
    (home / PIP_DIR / "pip.conf").write_text("\n".join(lines) + "\n")
    for path in (home, *home.rglob("*")):
        path.chmod(0o755 if path.is_dir() else 0o644)
    return ["-v", f"{home}:{BUILD_HOME}:ro"]


class StepClock:
    """Times the build's steps from the engine's output: Podman's ``STEP i/n: ...`` lines, or
    BuildKit's ``#k [i/n] ...`` and ``#k DONE 12.3s`` / ``#k CACHED`` lines (``--progress=plain``)."""

    PODMAN = re.compile(r"^STEP (\d+)/\d+: (.*)")
    BUILDKIT_START = re.compile(r"^#(\d+) \[(?:\S+ )?(\d+)/\d+\] (.*)")
    BUILDKIT_END = re.compile(r"^#(\d+) (DONE ([\d.]+)s|CACHED)")

    def __init__(self) -> None:
        self.steps: list[dict] = []
        self._open: dict | None = None
        self._buildkit: dict[str, dict] = {}

    def line(self, text: str, now: float) -> None:
        if match := self.PODMAN.match(text):
            self._close(now)
            self._open = {"step": int(match.group(1)), "instruction": match.group(2)[:200],
                          "seconds": 0.0, "cached": False, "started": now}
            self.steps.append(self._open)
        elif text.startswith("--> Using cache") and self._open is not None:
            self._open["cached"] = True
        elif text.startswith(("COMMIT", "Successfully tagged")):
            self._close(now)
        elif match := self.BUILDKIT_START.match(text):
            step = {"step": int(match.group(2)), "instruction": match.group(3)[:200], "seconds": 0.0,
                    "cached": False}
            self._buildkit[match.group(1)] = step
            self.steps.append(step)
        elif (match := self.BUILDKIT_END.match(text)) and match.group(1) in self._buildkit:
            step = self._buildkit.pop(match.group(1))
            step["cached"] = match.group(2) == "CACHED"
            step["seconds"] = float(match.group(3) or 0.0)

    def _close(self, now: float) -> None:
        if self._open is not None:
            self._open["seconds"] = round(now - self._open.pop("started"), 1)
            self._open = None


def build(engine: Engine, tag: str, no_cache: bool = False, echo=print) -> tuple[list[dict], float]:
    """Build the image; return (timed steps, seconds). Streams the engine's output; EngineError on failure."""
    options = engine.build_options()
    if no_cache:
        options.append("--no-cache")
    with tempfile.TemporaryDirectory(prefix="course-build-") as scratch:
        mounts = pip_mounts(Path(scratch), host_pip_settings())
        if mounts and engine.is_podman:
            echo("pip here trusts its own certificate authority: mounting it read-only into RUN steps")
            options += mounts
        elif mounts:
            echo("note: pip here trusts its own certificate authority, which `docker build` cannot mount; "
                 "pip inside the build may fail to verify the package index")
        env = dict(os.environ, BUILDKIT_PROGRESS="plain")
        argv = engine.command("build", *options, "--tag", tag, "--file", str(REPO / "Dockerfile"), str(REPO))
        echo("$ " + " ".join(argv))
        clock, started = StepClock(), time.monotonic()
        process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
        for line in process.stdout:
            clock.line(line.rstrip("\n"), time.monotonic())
            echo(line.rstrip("\n"))
        status = process.wait()
        clock.line("COMMIT", time.monotonic())
        seconds = time.monotonic() - started
    if status != 0:
        raise EngineError(f"the build failed ({engine.name} exit status {status}): see its output above")
    return clock.steps, seconds


def stage_seconds(steps: list[dict]) -> dict[str, float]:
    """Seconds of the named stages (STAGES), each the sum of the steps that run its command."""
    return {name: round(sum(s["seconds"] for s in steps if needle in s["instruction"]), 1)
            for name, needle in STAGES}


def summary(report: dict) -> str:
    """The report as a few lines for a person."""
    lines = [f"image {report['image']} ({report['engine']}): {report['size_bytes'] / 1e9:.2f} GB",
             f"base image: {report['base_seconds']:.0f} s"
             + (" (made locally)" if report["base_seconds"] else " (already present)")]
    for name, seconds in report["stages"].items():
        lines.append(f"{name}: {seconds:.0f} s")
    cached = sum(step["cached"] for step in report["steps"])
    lines.append(f"build: {report['build_seconds']:.0f} s in all ({len(report['steps'])} steps"
                 + (f", {cached} from the cache" if cached else "") + ")")
    return "\n".join(lines)


def build_image(tag: str = DEFAULT_TAG, no_cache: bool = False, report_path: Path = DEFAULT_REPORT,
                echo=print) -> dict:
    """Base image, build, size: the whole of ``make image``. Returns the report (also written as JSON)."""
    engine = find_engine()
    base_seconds = ensure_base_image(engine, echo)
    engine.probe(BASE_IMAGE)
    if engine.global_options:
        echo(f"{engine.name} runs containers here with {' '.join(engine.global_options)}")
    steps, seconds = build(engine, tag, no_cache, echo)
    report = {"engine": engine.name, "engine_options": engine.global_options, "image": tag,
              "size_bytes": engine.image_size(tag), "base_seconds": round(base_seconds, 1),
              "build_seconds": round(seconds, 1), "stages": stage_seconds(steps), "steps": steps}
    report_path.parent.mkdir(parents=True, exist_ok=True)
    report_path.write_text(json.dumps(report, indent=1) + "\n")
    return report


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tag", default=DEFAULT_TAG, help=f"the image's name (default {DEFAULT_TAG})")
    parser.add_argument("--no-cache", action="store_true", help="build every step afresh")
    parser.add_argument("--report", type=Path, default=DEFAULT_REPORT, help="where to write the JSON report")
    args = parser.parse_args(argv)
    try:
        report = build_image(args.tag, args.no_cache, args.report)
    except EngineError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    print(summary(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
