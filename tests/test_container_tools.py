"""The image tooling's own logic, without a container (tools/container): what ``make image`` reads
from the engine's output and from this machine, and what it hands the build."""

from __future__ import annotations

import resource
from pathlib import Path

import pytest

from tools.container import engine
from tools.container.base_image import debian_mirror
from tools.container.build_image import StepClock, pip_mounts, stage_seconds
from tools.container.engine import EngineError

PODMAN_OUTPUT = """STEP 1/4: FROM debian:bookworm-slim
STEP 2/4: RUN apt-get update && apt-get install --yes tini
Get:1 http://deb.debian.org/debian bookworm InRelease [151 kB]
--> 8296cbb4d5f
STEP 3/4: RUN make setup PYTHON=/usr/bin/python3
--> Using cache 87791b86080
--> 87791b86080
STEP 4/4: CMD ["jupyter", "lab"]
COMMIT ros2-course
"""
BUILDKIT_OUTPUT = """#5 [2/3] RUN apt-get update && apt-get install --yes tini
#5 12.70 Get:1 http://deb.debian.org/debian bookworm InRelease [151 kB]
#5 DONE 54.3s
#6 [3/3] RUN make setup PYTHON=/usr/bin/python3
#6 CACHED
"""


def test_build_steps_are_timed_from_podmans_output():
    clock = StepClock()
    for second, line in enumerate(PODMAN_OUTPUT.splitlines()):
        clock.line(line, 10.0 * second)  # one line every 10 s
    steps = {s["step"]: s for s in clock.steps}
    assert [s["step"] for s in clock.steps] == [1, 2, 3, 4]
    assert (steps[2]["seconds"], steps[2]["cached"]) == (30.0, False)  # its three lines
    assert (steps[3]["seconds"], steps[3]["cached"]) == (30.0, True)
    assert stage_seconds(clock.steps)["system packages"] == 30.0
    assert stage_seconds(clock.steps)["make setup"] == 30.0


def test_build_steps_are_timed_from_buildkits_output():
    clock = StepClock()
    for line in BUILDKIT_OUTPUT.splitlines():
        clock.line(line, 0.0)
    assert [(s["step"], s["seconds"], s["cached"]) for s in clock.steps] == [(2, 54.3, False), (3, 0.0, True)]


def test_the_mirror_is_read_from_apts_policy():
    policy = """Package files:
 100 /var/lib/dpkg/status
 500 http://deb.debian.org/debian-security bookworm-security/main amd64 Packages
 500 http://mirror.example.org/debian bookworm/main amd64 Packages
"""
    assert debian_mirror(policy) == "http://mirror.example.org/debian"
    with pytest.raises(EngineError, match="no source for Debian bookworm/main"):
        debian_mirror(policy.replace("bookworm/main", "trixie/main"))


def test_pip_gets_the_hosts_authority_and_index_but_no_host_paths(tmp_path: Path):
    authority = tmp_path / "ca.pem"
    authority.write_text("-----BEGIN CERTIFICATE-----\n")
    settings = {"cert": str(authority), "default-timeout": "180", "find-links": "/opt/wheels",
                "extra-index-url": "file:///opt/pypi/simple https://pypi.example.org/simple",
                "constraint": "/etc/xdg/pip/constraints.txt"}
    (scratch := tmp_path / "scratch").mkdir()
    mounts = pip_mounts(scratch, settings)
    assert mounts == ["-v", f"{scratch / 'home'}:/root:ro"]
    config = (scratch / "home" / ".config" / "pip" / "pip.conf").read_text().splitlines()
    assert config == ["[global]", "cert = /root/.config/pip/host-ca.pem",
                      "extra-index-url = https://pypi.example.org/simple", "default-timeout = 180"]
    assert (scratch / "home" / ".config" / "pip" / "host-ca.pem").read_text() == authority.read_text()
    assert pip_mounts(tmp_path, {"default-timeout": "180"}) == [], "no authority of its own: nothing to mount"


def test_ulimits_never_exceed_the_hard_limits_or_the_highest_pid():
    assert engine.hard_limits(nofile=4096, nproc=96365, pid_max=32768) == \
        ["--ulimit", "nofile=4096:4096", "--ulimit", "nproc=32768:32768"]
    assert engine.hard_limits(nofile=20000, nproc=1000, pid_max=32768)[-1] == "nproc=1000:1000"
    nofile = resource.getrlimit(resource.RLIMIT_NOFILE)[1]  # this machine's own
    if nofile != resource.RLIM_INFINITY:
        assert f"nofile={nofile}:{nofile}" in engine.hard_limits()
