"""Every container route builds and runs the one image (no container needed; ``make test-image`` runs it).

* Binder (repo2docker) and Dev Containers / Codespaces both build the Dockerfile at the root;
* both serve or forward JupyterLab's port, 8888, which the image's command listens on;
* ``classroom/values.yaml`` (Zero to JupyterHub) names the image that ``make image`` builds, and runs
  it the way the image expects: its entrypoint kept, ``jupyterhub-singleuser`` as the command, uid
  1000, and the working copy where the image makes it.
"""

from __future__ import annotations

import json
import os
import re
import shlex
from pathlib import Path

import yaml

from tools.container.base_image import BASE_IMAGE
from tools.container.build_image import DEFAULT_TAG

REPO = Path(__file__).resolve().parent.parent
PORT = 8888


def dockerfile_instructions(path: Path) -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) of a Dockerfile, continuation lines joined, comments left out."""
    instructions, pending = [], ""
    for line in path.read_text().splitlines():
        if not pending and (not line.strip() or line.lstrip().startswith("#")):
            continue
        pending += line.rstrip()
        if pending.endswith("\\"):
            pending = pending[:-1] + " "
            continue
        keyword, _, arguments = pending.strip().partition(" ")
        instructions.append((keyword.upper(), " ".join(arguments.split())))
        pending = ""
    return instructions


def exec_form(arguments: str) -> list[str]:
    """The argv of an exec-form CMD or ENTRYPOINT (a JSON array); a shell form fails the test."""
    assert arguments.startswith("["), f"use the exec form (a JSON array), not a shell form: {arguments}"
    return json.loads(arguments)


def env_values(instructions) -> dict[str, str]:
    values = {}
    for keyword, arguments in instructions:
        if keyword == "ENV":
            values.update(dict(pair.split("=", 1) for pair in shlex.split(arguments)))
    return values


def last(instructions, wanted: str) -> str:
    found = [arguments for keyword, arguments in instructions if keyword == wanted]
    assert found, f"the Dockerfile has no {wanted}"
    return found[-1]


def repo2docker_dockerfile(repo: Path) -> Path | None:
    """The Dockerfile repo2docker builds: in binder/ or .binder/ when one exists, else at the root."""
    for folder in ("binder", ".binder"):
        if (repo / folder).is_dir():
            candidate = repo / folder / "Dockerfile"
            return candidate if candidate.is_file() else None
    candidate = repo / "Dockerfile"
    return candidate if candidate.is_file() else None


def devcontainer(repo: Path) -> dict:
    return json.loads((repo / ".devcontainer" / "devcontainer.json").read_text())


def makefile_image(repo: Path) -> str:
    match = re.search(r"^IMAGE\s*\?=\s*(\S+)", (repo / "Makefile").read_text(), re.MULTILINE)
    assert match, "the Makefile sets no IMAGE"
    return match.group(1)


def test_binder_and_dev_containers_build_the_same_dockerfile():
    binder = repo2docker_dockerfile(REPO)
    assert binder == REPO / "Dockerfile", f"repo2docker would build {binder}, not the root Dockerfile"
    config = devcontainer(REPO)
    folder = REPO / ".devcontainer"
    assert (folder / config["build"]["dockerfile"]).resolve() == binder
    assert (folder / config["build"]["context"]).resolve() == REPO, "the build context is not the repository"
    assert "image" not in config, "a prebuilt image beside the build: two sources for one environment"


def test_every_route_serves_jupyterlab_on_port_8888():
    instructions = dockerfile_instructions(REPO / "Dockerfile")
    env = env_values(instructions)
    command = exec_form(last(instructions, "CMD"))
    assert command[:2] == ["jupyter", "lab"] and "--ip=0.0.0.0" in command, command
    assert not any(arg.startswith("--port") for arg in command), "the port comes from JUPYTER_PORT alone"
    assert env.get("JUPYTER_PORT") == str(PORT)
    assert str(PORT) in last(instructions, "EXPOSE").split()
    config = devcontainer(REPO)
    assert PORT in config["forwardPorts"]
    assert config.get("overrideCommand") is False, "Dev Containers would replace the image's command"
    assert f"--notebook-dir={env['ROS2_COURSE_WORK']}" in command, "JupyterLab does not open the working copy"


def test_the_image_runs_as_jovyan_uid_1000_under_tini_and_the_start_script():
    instructions = dockerfile_instructions(REPO / "Dockerfile")
    assert instructions[0] == ("FROM", BASE_IMAGE.removeprefix("docker.io/library/"))
    assert last(instructions, "USER") == "1000"
    users = [arguments for keyword, arguments in instructions if keyword == "RUN" and "useradd" in arguments]
    assert users and "--uid 1000" in users[0] and users[0].endswith(" jovyan"), users
    entrypoint = exec_form(last(instructions, "ENTRYPOINT"))
    assert entrypoint[0] == "tini" and entrypoint[-1].startswith("/opt/ros2-course/"), entrypoint
    script = REPO / entrypoint[-1].removeprefix("/opt/ros2-course/")
    assert script.is_file() and os.access(script, os.X_OK), f"{script} is missing or not executable"
    config = devcontainer(REPO)
    assert config["remoteUser"] == config["containerUser"] == "jovyan"
    env = env_values(instructions)
    assert env["ROS2_COURSE_WORK"].startswith("/home/jovyan/")


def test_zero_to_jupyterhub_runs_the_image_make_image_builds():
    values = yaml.safe_load((REPO / "classroom" / "values.yaml").read_text())["singleuser"]
    env = env_values(dockerfile_instructions(REPO / "Dockerfile"))
    assert makefile_image(REPO) == DEFAULT_TAG
    assert values["image"]["name"].rsplit("/", 1)[-1] == DEFAULT_TAG, values["image"]
    # The chart's cmd becomes the container's arguments: the image's entrypoint still syncs first.
    assert values["cmd"] == ["jupyterhub-singleuser"], values["cmd"]
    assert "jupyterhub==" in (REPO / "environment.txt").read_text(), "the image has no jupyterhub-singleuser"
    assert values.get("uid", 1000) == 1000
    assert values["extraEnv"]["ROS2_COURSE_WORK"] == env["ROS2_COURSE_WORK"]
    work = env["ROS2_COURSE_WORK"].removeprefix("/home/jovyan/")
    url = values["defaultUrl"]
    assert url.startswith(f"/lab/tree/{work}/"), url
    assert (REPO / "notebooks" / url.removeprefix(f"/lab/tree/{work}/")).is_file(), url
