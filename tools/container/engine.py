"""The container engine on this machine: Docker or Podman, whichever works, and how to call it.

``find_engine()`` returns the first engine that answers (``docker info`` needs a running daemon, so a
Docker client without one is passed over; ``podman info`` needs none). ``CONTAINER_ENGINE=podman``
(or ``docker``) picks one. ``Engine.probe(image)`` then starts a throw-away container and, when the
engine's defaults fail, retries with the settings a restricted host needs:

* Podman asks for more open files than the hard limit (1048576) and fails where raising a limit is
  not permitted: ``--ulimit nofile=N:N --ulimit nproc=N:N``, N being the current hard limits, which
  is always allowed and changes nothing elsewhere;
* hybrid cgroup hierarchies refuse crun, and a host without systemd has no systemd cgroup manager:
  ``--runtime runc --cgroup-manager cgroupfs`` (only when runc is installed).

Builds and most test containers share the host's network (``--network host``): the build reaches
the package mirrors as the host does, and the course's ROS domain reservations (abstract Unix
sockets, which belong to a network namespace) then hold across the host and the container alike.
Only the standard library: ``make image`` runs before any venv exists.
"""

from __future__ import annotations

import os
import resource
import shutil
import subprocess
from dataclasses import dataclass, field

ENGINES = ("docker", "podman")
ENGINE_ENV = "CONTAINER_ENGINE"


class EngineError(RuntimeError):
    """No engine works, or one failed; the message says what was tried and what to install."""


@dataclass
class Engine:
    """One container engine (``docker`` or ``podman``) and the options this host needs for it."""

    name: str
    global_options: list[str] = field(default_factory=list)  # before the subcommand (podman)
    limits: list[str] = field(default_factory=list)  # --ulimit ... for build and run

    @property
    def is_podman(self) -> bool:
        return self.name == "podman"

    def command(self, subcommand: str, *args: str) -> list[str]:
        """The argv of ``ENGINE [global options] SUBCOMMAND ARGS``."""
        return [self.name, *self.global_options, subcommand, *args]

    def run_options(self, host_network: bool = True) -> list[str]:
        """Options for ``run``: the limits this host needs, and the host's network unless told not to."""
        return [*(["--network", "host"] if host_network else []), *self.limits]

    def build_options(self) -> list[str]:
        """Options for ``build``: as for ``run``; Podman never asks a registry (the base is local)."""
        options = ["--network", "host", *self.limits]
        return [*options, "--pull=never"] if self.is_podman else options

    def has_image(self, image: str) -> bool:
        return self.call("image", "inspect", image).returncode == 0

    def image_size(self, image: str) -> int:
        """The image's size in bytes, as the engine reports it."""
        done = self.call("image", "inspect", "--format", "{{.Size}}", image, check=True)
        return int(done.stdout.split()[0])

    def call(self, subcommand: str, *args: str, check: bool = False, timeout: float | None = 120,
             **kwargs) -> subprocess.CompletedProcess:
        """Run ``ENGINE SUBCOMMAND ARGS`` and capture its output (text)."""
        argv = self.command(subcommand, *args)
        done = subprocess.run(argv, capture_output=True, text=True, timeout=timeout, **kwargs)
        if check and done.returncode != 0:
            raise EngineError(f"`{' '.join(argv)}` failed ({done.returncode}):\n{done.stderr[-3000:]}")
        return done

    def probe(self, image: str) -> None:
        """Start a container of ``image``; on failure, retry with a restricted host's settings.

        Keeps the first settings that work; raises EngineError with both errors otherwise.
        """
        first = self._try_run(image)
        if first is None:
            return
        if not self.is_podman:
            raise EngineError(f"docker cannot start a container of {image}:\n{first}")
        restricted = ["--cgroup-manager", "cgroupfs"]
        if shutil.which("runc"):
            restricted = ["--runtime", "runc", *restricted]
        self.global_options = restricted
        second = self._try_run(image)
        if second is not None:
            raise EngineError(f"podman cannot start a container of {image}, with its defaults:\n{first}\n"
                              f"nor with {' '.join(restricted)}:\n{second}")

    def _try_run(self, image: str) -> str | None:
        done = self.call("run", "--rm", *self.run_options(), image, "true")
        return None if done.returncode == 0 else (done.stderr.strip() or f"exit status {done.returncode}")


def _answers(name: str) -> bool:
    if shutil.which(name) is None:
        return False
    try:
        return subprocess.run([name, "info"], capture_output=True, timeout=60).returncode == 0
    except subprocess.TimeoutExpired:
        return False


def hard_limits(nofile: int | None = None, nproc: int | None = None, pid_max: int | None = None) -> list[str]:
    """``--ulimit`` options: open files and processes at this process's hard limits.

    The process limit is also capped at the kernel's highest PID (no more processes can exist): a
    sandboxed kernel refused an RLIMIT_NPROC above ``kernel.pid_max`` although the hard limit was higher.
    The arguments stand in for this machine's values (read when not given; None when unlimited).
    """
    def hard(limit: int) -> int | None:
        value = resource.getrlimit(limit)[1]
        return None if value == resource.RLIM_INFINITY else value

    nofile = nofile if nofile is not None else hard(resource.RLIMIT_NOFILE)
    nproc = nproc if nproc is not None else hard(resource.RLIMIT_NPROC)
    pid_max = pid_max if pid_max is not None else _pid_max()
    options = []
    for name, caps in (("nofile", [nofile]), ("nproc", [nproc, pid_max])):
        caps = [cap for cap in caps if cap is not None]
        if caps:
            options += ["--ulimit", f"{name}={min(caps)}:{min(caps)}"]
    return options


def _pid_max() -> int | None:
    try:
        with open("/proc/sys/kernel/pid_max") as handle:
            return int(handle.read())
    except (OSError, ValueError):
        return None


def find_engine() -> Engine:
    """The first working engine (``$CONTAINER_ENGINE`` first when set); EngineError if none works."""
    wanted = os.environ.get(ENGINE_ENV)
    if wanted and wanted not in ENGINES:
        raise EngineError(f"{ENGINE_ENV}={wanted!r}: the engines known here are {', '.join(ENGINES)}")
    candidates = (wanted,) if wanted else ENGINES
    for name in candidates:
        if _answers(name):
            return Engine(name, limits=hard_limits() if name == "podman" else [])
    found = [name for name in candidates if shutil.which(name)]
    detail = (f"{' and '.join(found)} found, but `{found[0]} info` fails (a Docker client needs a running "
              "daemon)" if found else "neither docker nor podman is installed")
    raise EngineError(f"no working container engine: {detail}. Install Docker, or Podman "
                      "(Debian/Ubuntu: apt-get install podman runc uidmap).")
