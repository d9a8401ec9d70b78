"""The real ``colcon build`` of a workspace, and what it did (:class:`ColconBuild`)."""

from __future__ import annotations

import re
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from course_helpers.core import processes

COLCON_TIMEOUT_S = 300.0


@dataclass
class ColconBuild:
    """What one ``colcon build`` did: exit code, packages and the type colcon gave each."""

    returncode: int
    seconds: float
    package_types: dict[str, str]  # package name -> 'ros.ament_python', 'python', ...
    finished: list[str]
    failed: list[str]
    output: str
    log_dir: Path

    @property
    def ok(self) -> bool:
        """True when colcon exited with 0."""
        return self.returncode == 0

    def summary(self) -> str:
        """A stable one-line-per-package summary (no timings)."""
        lines = [f"colcon build {'succeeded' if self.ok else 'FAILED'}"]
        for name in sorted(self.package_types):
            state = "finished" if name in self.finished else (
                "failed" if name in self.failed else "not built")
            lines.append(f"  {name:<22} {self.package_types[name]:<18} {state}")
        return "\n".join(lines)

    def log_tail(self, lines: int = 25) -> str:
        """The last ``lines`` lines colcon printed, plus the failed packages' own error output."""
        text = self.output.splitlines()[-lines:]
        for name in self.failed:
            stderr = self.log_dir / "latest_build" / name / "stdout_stderr.log"
            if stderr.is_file():
                text += [f"--- {name} output ---"]
                text += stderr.read_text(errors="replace").splitlines()[-lines:]
        return "\n".join(text)


def colcon_command(src: Path, build_base: Path, install_base: Path, log_base: Path,
                   packages: list[str] | None = None) -> list[str]:
    """The ``colcon build`` command line that reads ``src`` and writes into the three other folders
    (only ``packages``, if given)."""
    colcon = shutil.which("colcon", path=str(Path(sys.executable).parent)) or "colcon"
    command = [colcon, "--log-base", str(log_base), "build",
               "--base-paths", str(src),
               "--build-base", str(build_base),
               "--install-base", str(install_base),
               "--event-handlers", "console_stderr-"]
    if packages:
        command += ["--packages-select", *packages]
    return command


def run_colcon(command: list[str], cwd: Path, log_base: Path,
               progress: Callable[[str], None] | None = None,
               timeout: float = COLCON_TIMEOUT_S) -> ColconBuild:
    """Run ``command`` (from :func:`colcon_command`) in ``cwd`` to its end; what it did.

    ``progress`` gets '$ colcon build', then each line colcon prints, then 'done' or 'FAILED'.
    Raises CourseError if it takes longer than ``timeout`` seconds.
    """
    env = {"PYTHONDONTWRITEBYTECODE": "1", "COLCON_HOME": None}
    started = time.monotonic()
    report = progress or (lambda _line: None)
    report("$ colcon build")
    returncode, output = processes.run(command, env=env, cwd=str(cwd), timeout=timeout, on_line=report)
    result = ColconBuild(
        returncode=returncode,
        seconds=time.monotonic() - started,
        package_types=_package_types(log_base / "latest_build" / "logger_all.log"),
        finished=re.findall(r"^Finished <<< (\S+)", output, re.MULTILINE),
        failed=re.findall(r"^Failed\s+<<< (\S+)", output, re.MULTILINE),
        output=output,
        log_dir=log_base,
    )
    report("done" if result.ok else "FAILED")
    return result


def _package_types(logger_all: Path) -> dict[str, str]:
    """Package name -> type that colcon identified ('ros.ament_python', 'python', ...)."""
    try:
        text = logger_all.read_text(errors="replace")
    except OSError:
        return {}
    found = re.findall(r"Package '[^']*' with type '([^']+)' and name '([^']+)'", text)
    return {name: kind for kind, name in found}
