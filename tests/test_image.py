"""The course's container image, run the ways students and hubs run it (``make test-image``).

Every check starts a real container of the image (Docker or Podman, tools/container/engine.py) as
the image's own user, jovyan (uid 1000), through its entrypoint:

* the course in /opt/ros2-course cannot be written, the home and the working copy can, and the home
  holds the notebooks as built;
* an empty volume mounted over the working copy is filled at start, and a student's edit survives
  the next start;
* strict nbval of every notebook (each run twice, as ``make notebooks`` does) passes inside it;
* the README's ``docker run`` line (port 8888 published, the work in a named volume) serves
  JupyterLab at the address it prints, and Chromium on the host (Playwright, as the QoS lab's
  browser test) runs notebook 00 in it from a clean slate without an error;
* a real JupyterHub starts the image as a student's server with ``jupyterhub-singleuser`` (Binder's
  and Zero to JupyterHub's command), which answers through the hub's proxy;
* the ROS 1 packages and network tools a later chapter needs are installed.

Needs the image's name in ``COURSE_IMAGE`` (``make test-image`` builds the image and sets it);
skipped otherwise, with the reason. Containers share the host's network (engine.py says why), except
the README's own line, which publishes a port.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from course_helpers.core.waiting import poll_until
from tools.container.engine import Engine, find_engine
from tools.servers import free_port

from .browsers import HANG_MS, artifact, browser_page, require_chromium
from .lab_page import assert_no_nbgrader_ui, menu
from .servers import ContainerServer, http_get, jupyterhub, shut_down_kernels

IMAGE = os.environ.get("COURSE_IMAGE")
REPO = Path(__file__).resolve().parent.parent
COURSE = "/opt/ros2-course"
HOME = "/home/jovyan"
WORK = f"{HOME}/ros2-course-work"
JOBS = os.environ.get("COURSE_IMAGE_JOBS", "6")  # nbval workers inside the container (make's NB_JOBS)

if not IMAGE:
    pytest.skip("no image to test: `make test-image` builds the course's image and runs these tests "
                "(COURSE_IMAGE names the image)", allow_module_level=True)
pytestmark = pytest.mark.image


@pytest.fixture(scope="module")
def engine() -> Engine:
    found = find_engine()
    found.probe(IMAGE)  # the settings this host needs to start a container
    return found


def run(engine: Engine, *args: str, timeout: float = 120, check: bool = True):
    """``ENGINE run --rm [host settings] ARGS`` (the image and its command among ARGS); returns the result."""
    done = engine.call("run", "--rm", *engine.run_options(), *args, timeout=timeout)
    if check:
        assert done.returncode == 0, \
            f"exit status {done.returncode}:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return done


def last_json(output: str) -> dict:
    """The JSON object on the last line of a container's output (the entrypoint's sync report comes first)."""
    return json.loads(output.strip().splitlines()[-1])


def working_files(folder: Path) -> list[str]:
    """The notebooks and data files in ``folder`` (a working copy, or the course's notebooks/)."""
    return sorted(str(p.relative_to(folder)) for p in [*folder.glob("*.ipynb"), *folder.glob("config/*")])


def course_files() -> list[str]:
    """What a working copy holds: the course's notebooks and their data files."""
    return working_files(REPO / "notebooks")


PROBE = r"""
import json, os, pathlib, shutil, sysconfig
def writable(directory):
    probe = pathlib.Path(directory) / ".write-probe"
    try:
        probe.write_text("x")
    except OSError:
        return False
    probe.unlink()
    return True
work = pathlib.Path(os.environ["ROS2_COURSE_WORK"])
print(json.dumps({
    "uid": os.getuid(), "home": os.environ["HOME"], "cwd": os.getcwd(), "work": str(work),
    "writable": {d: writable(d) for d in DIRS},
    "owner": {d: os.stat(d).st_uid for d in DIRS},
    "programs": {p: shutil.which(p) for p in ("python", "jupyter", "jupyterhub-singleuser")},
    "files": sorted(str(p.relative_to(work)) for p in [*work.glob("*.ipynb"), *work.glob("config/*")]),
}))
"""
READ_ONLY = [COURSE, f"{COURSE}/notebooks", f"{COURSE}/course_helpers", f"{COURSE}/.venv/bin",
             f"{COURSE}/.venv/lib/python3.11/site-packages"]
WRITABLE = [HOME, WORK, "/tmp"]


def test_course_is_read_only_and_the_work_is_writable(engine):
    code = PROBE.replace("DIRS", repr(READ_ONLY + WRITABLE))
    found = last_json(run(engine, IMAGE, "python", "-c", code).stdout)
    print(json.dumps(found, indent=1))
    assert (found["uid"], found["home"], found["cwd"], found["work"]) == (1000, HOME, HOME, WORK)
    assert [d for d in READ_ONLY if found["writable"][d]] == [], "the student can change the course"
    assert [d for d in READ_ONLY if found["owner"][d] != 0] == [], "the course is not root's"
    assert [d for d in WRITABLE if not found["writable"][d]] == [], "the student cannot write their work"
    assert found["programs"] == {p: f"{COURSE}/.venv/bin/{p}" for p in found["programs"]}
    assert found["files"] == course_files(), "the home does not hold the course's notebooks as built"


def test_an_empty_volume_gets_the_working_copy_and_keeps_the_students_edits(engine):
    if os.geteuid() != 0:
        pytest.skip("giving a fresh volume to uid 1000, as a hub does, needs root")
    volume = Path(tempfile.mkdtemp(prefix="course-image-volume-"))
    try:
        os.chown(volume, 1000, 100)  # a hub's fresh volume: empty, the student's
        first = run(engine, "--volume", f"{volume}:{WORK}", IMAGE, "true")
        assert working_files(volume) == course_files(), first.stdout
        assert "00_welcome.ipynb: copied" in first.stdout
        assert {p.stat().st_uid for p in volume.rglob("*")} == {1000}, "the working copy is not the student's"
        notebook = volume / "00_welcome.ipynb"
        edited = json.loads(notebook.read_text())
        cell = next(c for c in edited["cells"] if c["cell_type"] == "code")
        cell["source"] = "print('my own experiment')\n"
        notebook.write_text(json.dumps(edited))
        second = run(engine, "--volume", f"{volume}:{WORK}", IMAGE, "true")
        kept = json.loads(notebook.read_text())
        assert any(c.get("id") == cell.get("id") and c["source"] == cell["source"] for c in kept["cells"]), \
            second.stdout
    finally:
        shutil.rmtree(volume, ignore_errors=True)


def test_ros1_and_network_tools_for_later_chapters(engine):
    script = ("/usr/bin/python3 -c 'import rospy, rosgraph, rosmaster, rosnode, rostopic, std_msgs.msg; "
              "print(\"ros1 ok\")' && ip -V && nft --version")
    done = run(engine, IMAGE, "sh", "-c", script)
    assert "ros1 ok" in done.stdout and "iproute2" in done.stdout and "nftables" in done.stdout, done.stdout


# Strict nbval of every notebook, as `make notebooks` runs it, in a scratch copy: the course itself
# is read-only. The copy brings the notebooks' conftest.py (the second run of every notebook), the
# sanitizer and the root conftest.py with tests/durations.json (longest notebooks first).
NBVAL = f"""set -e
mkdir -p /tmp/course-nbval/tests
cd {COURSE}
cp -r notebooks conftest.py pyproject.toml /tmp/course-nbval/
cp tests/nbval_sanitize.cfg tests/durations.json /tmp/course-nbval/tests/
cd /tmp/course-nbval
exec python -m pytest --nbval --nbval-current-env --nbval-sanitize-with tests/nbval_sanitize.cfg \
  --nbval-cell-timeout=120 -p no:cacheprovider -n {JOBS} --dist loadfile --no-loadscope-reorder notebooks -q
"""


@pytest.mark.timeout(1800)
def test_every_notebook_passes_strict_nbval_inside(engine):
    name = f"course-image-nbval-{secrets.token_hex(4)}"
    argv = engine.command("run", "--rm", "--name", name, *engine.run_options(), IMAGE, "sh", "-c", NBVAL)
    started, lines, load_before = time.monotonic(), [], os.getloadavg()[0]
    process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        for line in process.stdout:  # pytest's progress, as it comes
            print(line, end="", flush=True)
            lines.append(line.rstrip("\n"))
        status = process.wait()
    finally:
        if process.poll() is None:  # interrupted (the test's timeout): stop the container too
            engine.call("rm", "--force", name)
            process.kill()
    tail = "\n".join(lines[-25:])
    # Timed cells assert what they measure; on a machine shared with other jobs, say how busy it was.
    print(f"strict nbval inside the image ({JOBS} workers): {time.monotonic() - started:.0f} s; load "
          f"average {load_before:.1f} before, {os.getloadavg()[0]:.1f} after, on {os.cpu_count()} CPUs")
    assert status == 0, tail
    assert re.search(r"\d+ passed", lines[-1]) and "failed" not in lines[-1], tail


@pytest.fixture(scope="module")
def lab(engine):
    """The README's `docker run` line, detached: the image's default command (JupyterLab) on port 8888
    published on the host's localhost, the working copy in a named volume, the token read from the log
    as a user reads the address it prints. Yields (base URL, token, Server); afterwards shuts the kernels
    down, stops the container and removes the volume.
    """
    volume = f"course-image-test-work-{secrets.token_hex(4)}"
    server = ContainerServer(engine, IMAGE, [*engine.run_options(host_network=False), "--publish",
                                             "127.0.0.1:{port}:8888", "--volume", f"{volume}:{WORK}"])
    base, token = f"http://127.0.0.1:{server.port}", None
    try:
        server.wait_for(f"{base}/api")
        printed = re.search(r"http://127\.0\.0\.1:8888/lab\?token=(\w+)", server.logs())
        assert printed, f"JupyterLab printed no address with its token:\n{server.logs()[-3000:]}"
        token = printed.group(1)
        yield base, token, server
    finally:
        try:
            if token:
                shut_down_kernels(base, token)
        finally:
            print(server.logs()[-2000:])
            code = server.stop()
            engine.call("volume", "rm", "--force", volume)
    assert code != 137, "JupyterLab did not stop within 20 s of SIGTERM and was killed"


def test_jupyterlab_answers_over_http(lab):
    base, token, server = lab
    status, _, body = http_get(f"{base}/api/status", token)
    assert status == 200 and "started" in json.loads(body), body
    status, _, body = http_get(f"{base}/api/contents", token)
    names = {item["name"] for item in json.loads(body)["content"]} if status == 200 else set()
    assert "00_welcome.ipynb" in names, (status, body)
    status, _, body = http_get(f"{base}/lab?token={token}")
    assert status == 200 and "JupyterLab" in body, status
    assert http_get(f"{base}/api/contents")[0] == 403, "JupyterLab answers without its token"
    assert f"working copy {WORK} is up to date" in server.logs()


@pytest.mark.browser
def test_notebook_00_runs_in_a_browser(lab):
    require_chromium()
    base, token, _ = lab
    with browser_page(on_failure="image_notebook_00_failure.png") as page:
        _run_notebook_00(page, base, token)


def _put_setting(base: str, token: str, plugin: str, values: dict) -> None:
    """Store a JupyterLab user setting through the server's settings API (as the Settings editor does)."""
    body = json.dumps({"raw": json.dumps(values)}).encode()
    request = urllib.request.Request(f"{base}/lab/api/settings/{plugin}?token={token}", data=body,
                                     method="PUT", headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=10) as response:
        assert response.status == 204, response.status


def _run_notebook_00(page, base: str, token: str) -> None:
    # Every cell in the page (no virtual scrolling), so that every cell's prompt can be read.
    _put_setting(base, token, "@jupyterlab/notebook-extension:tracker", {"windowingMode": "none"})
    page.goto(f"{base}/lab/tree/00_welcome.ipynb?token={token}", timeout=HANG_MS)
    page.wait_for_selector(".jp-Notebook .jp-CodeCell", timeout=HANG_MS)
    page.locator(".jp-StatusBar-Item", has_text="Idle").first.wait_for(timeout=HANG_MS)
    assert_no_nbgrader_ui(page)  # the image's JupyterLab is the student's, as make lab's
    prompts = page.locator(".jp-Notebook .jp-CodeCell .jp-InputPrompt")
    menu(page, "Edit", "Clear Outputs of All Cells")  # so that every output seen below is new
    cells = prompts.count()
    assert cells > 0 and page.locator(".jp-Notebook .jp-OutputArea-output").count() == 0
    assert not any(re.search(r"\d", text) for text in prompts.all_inner_texts()), "outputs were not cleared"
    started = time.monotonic()
    menu(page, "Run", "Run All Cells")

    def finished() -> bool:  # every cell ran, or the run stopped (an error stops "Run All")
        texts = prompts.all_inner_texts()
        return all(re.search(r"\[\d+\]", t) for t in texts) or (
            any(re.search(r"\d", t) for t in texts) and not any("*" in t for t in texts)
            and page.locator(".jp-StatusBar-Item", has_text="Idle").count() > 0)

    poll_until(finished, 180, period=0.5)
    seconds = time.monotonic() - started
    page.locator(".jp-StatusBar-Item", has_text="Idle").first.wait_for(timeout=HANG_MS)
    page.screenshot(path=artifact("image_notebook_00.png"), full_page=True)
    texts = prompts.all_inner_texts()
    errors = page.locator(".jp-OutputArea-output[data-mime-type='application/vnd.jupyter.stderr']")
    outputs = "\n".join(page.locator(".jp-Notebook .jp-OutputArea").all_inner_texts())
    print(f"notebook 00: {cells} code cells run in the browser in {seconds:.1f} s")
    assert errors.count() == 0, "\n---\n".join(errors.all_inner_texts())
    assert "Traceback" not in outputs and "Error" not in outputs.replace("CourseError", ""), outputs[-3000:]
    counts = [int(re.search(r"\[(\d+)\]", t).group(1)) for t in texts if re.search(r"\[(\d+)\]", t)]
    assert counts == list(range(1, cells + 1)), f"not every cell ran, in order, in a fresh kernel: {texts}"


# A real JupyterHub (the venv's, with configurable-http-proxy) whose spawner runs each server as a
# container of the image the way Zero to JupyterHub's KubeSpawner does: the hub's JUPYTERHUB_*
# variables passed in, `jupyterhub-singleuser` as the command, the image's entrypoint kept.
HUB_CONFIG = """
import json, os
from jupyterhub.spawner import SimpleLocalProcessSpawner

S = json.loads(os.environ["COURSE_IMAGE_HUB"])


class ImageSpawner(SimpleLocalProcessSpawner):
    async def start(self):
        names = sorted(n for n in self.get_env() if n.startswith(("JUPYTERHUB_", "JPY_")))
        self.cmd = [*S["run"], "--name", S["container"], *[f"--env={n}" for n in names], S["image"],
                    "jupyterhub-singleuser"]
        return await super().start()


c.JupyterHub.ip = c.JupyterHub.hub_ip = "127.0.0.1"
c.JupyterHub.port, c.JupyterHub.hub_port = S["port"], S["hub_port"]
c.ConfigurableHTTPProxy.command = [S["proxy"]]
c.ConfigurableHTTPProxy.api_url = f"http://127.0.0.1:{S['proxy_api_port']}"
c.ConfigurableHTTPProxy.pid_file = os.path.join(S["dir"], "proxy.pid")
c.JupyterHub.db_url = "sqlite:///" + os.path.join(S["dir"], "hub.sqlite")
c.JupyterHub.cookie_secret_file = os.path.join(S["dir"], "cookie_secret")
c.JupyterHub.spawner_class = ImageSpawner
c.SimpleLocalProcessSpawner.home_dir_template = S["dir"]
c.Spawner.start_timeout = c.Spawner.http_timeout = 180
c.Authenticator.allowed_users = {"student"}
c.JupyterHub.services = [{"name": "image-test", "api_token": S["token"]}]
c.JupyterHub.load_roles = [{"name": "image-test", "services": ["image-test"],
                            "scopes": ["admin:users", "admin:servers", "access:servers"]}]
"""
HUB_PROXY = REPO / ".venv" / "node" / "node_modules" / ".bin" / "configurable-http-proxy"


def _hub_api(base: str, token: str, path: str, method: str = "GET"):
    request = urllib.request.Request(f"{base}/hub/api{path}", method=method,
                                     headers={"Authorization": f"token {token}"})
    with urllib.request.urlopen(request, timeout=30) as response:
        body = response.read()
        return response.status, json.loads(body) if body else None


@pytest.mark.timeout(600)
def test_jupyterhub_runs_the_image_as_a_single_user_server(engine):
    proxy = shutil.which("configurable-http-proxy") or (str(HUB_PROXY) if HUB_PROXY.exists() else None)
    if proxy is None:
        pytest.skip("configurable-http-proxy (npm) is missing: npm install --prefix .venv/node "
                    "configurable-http-proxy@5.3.0")
    folder = Path(tempfile.mkdtemp(prefix="course-image-hub-"))
    token, port = secrets.token_hex(16), free_port()
    settings = {"run": engine.command("run", "--rm", *engine.run_options()), "image": IMAGE,
                "container": f"course-image-hub-{secrets.token_hex(4)}", "proxy": proxy, "dir": str(folder),
                "token": token, "port": port, "hub_port": free_port(), "proxy_api_port": free_port()}
    (folder / "jupyterhub_config.py").write_text(HUB_CONFIG)
    base = f"http://127.0.0.1:{port}"

    def hub_log() -> str:
        return (folder / "hub.log").read_text(errors="replace")

    def server() -> dict | None:
        return _hub_api(base, token, "/users/student")[1]["servers"].get("")

    command = [str(Path(sys.executable).parent / "jupyterhub"), "-f", "jupyterhub_config.py"]
    hub_env = dict(os.environ, COURSE_IMAGE_HUB=json.dumps(settings))
    try:
        with jupyterhub(command, base, folder / "hub.log", cwd=folder, env=hub_env):
            started = time.monotonic()
            assert _hub_api(base, token, "/users/student/server", method="POST")[0] in (201, 202)
            if not poll_until(lambda: (server() or {}).get("ready"), 180, period=1):
                pytest.fail(f"the student's server did not become ready:\n{hub_log()[-6000:]}")
            print(f"the hub started the image's single-user server in {time.monotonic() - started:.1f} s")
            prefix = f"{base}/user/student"
            # Through the proxy; the server asks the hub whether the token may use it.
            status, _, body = http_get(f"{prefix}/api/status", token)
            assert status == 200 and "started" in json.loads(body), (status, body)
            status, _, body = http_get(f"{prefix}/api/contents/ros2-course-work", token)
            names = {item["name"] for item in json.loads(body)["content"]} if status == 200 else set()
            assert "00_welcome.ipynb" in names, (status, body[:2000])
            status, headers, _ = http_get(f"{prefix}/lab")  # no login: off to the hub's OAuth
            assert status == 302 and "/hub/api/oauth2/authorize" in headers.get("Location", ""), \
                (status, headers)
            assert f"working copy {WORK} is up to date" in hub_log()
            assert _hub_api(base, token, "/users/student/server", method="DELETE")[0] in (202, 204)
            assert poll_until(lambda: server() is None, 60, period=1), "the hub did not stop the server"
            def containers() -> str:
                return engine.call("ps", "--all", "--filter", f"name={settings['container']}",
                                   "--format", "{{.Names}}").stdout.strip()
            assert poll_until(lambda: not containers(), 30), f"the server's container is left: {containers()}"
    finally:
        engine.call("rm", "--force", settings["container"])
        print(hub_log()[-1500:])
        shutil.rmtree(folder, ignore_errors=True)
