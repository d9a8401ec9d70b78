"""``rt.shutdown_other_kernels()``: shut this user's other course kernels of this Jupyter server down,
through the server's own REST API, and say in one line what was done.

Which kernels: :func:`.other_kernels.other_kernels` (processes of this user, children of this kernel's
parent, holding a course domain): never another user's, never another server's. The server is this
kernel's parent; its runtime file ``jpserver-<pid>.json`` (in Jupyter's runtime folder, where the
kernel's own connection file is too) holds its port, base URL and token. A kernel's id is in its
command line (``-f .../kernel-<id>.json``), and is used only when the server lists it among its
kernels. ``DELETE /api/kernels/<id>`` is what JupyterLab's Running panel does: the server asks the
kernel to shut down, so the kernel stops its nodes and child processes itself (a kernel killed from
outside would be restarted by the server). Then this waits until each kernel and its child processes
have ended.
"""

from __future__ import annotations

import json
import os
import re
import urllib.error
import urllib.request

from course_helpers.core.other_kernels import OtherKernel, other_kernels

STOP_WAIT_S = 30.0  # a kernel stops its nodes and children, then exits; a busy machine is slow
_KERNEL_ID = re.compile(r"kernel-([0-9a-f-]{36})\.json$")


def runtime_dir() -> str:
    """Jupyter's runtime folder (``JUPYTER_RUNTIME_DIR`` or jupyter_core's default)."""
    from jupyter_core.paths import jupyter_runtime_dir

    return jupyter_runtime_dir()


def this_server() -> dict | None:
    """The runtime file of the Jupyter server that started this kernel (its parent), or None."""
    path = os.path.join(runtime_dir(), f"jpserver-{os.getppid()}.json")
    try:
        with open(path, encoding="utf-8") as handle:
            return json.load(handle)
    except (OSError, ValueError):
        return None


def kernel_id(pid: int) -> str | None:
    """The Jupyter kernel id in the command line of process ``pid`` (its connection file's name)."""
    import psutil

    try:
        for part in psutil.Process(pid).cmdline():
            found = _KERNEL_ID.search(part)
            if found:
                return found.group(1)
    except psutil.Error:
        pass
    return None


def _api(server: dict, path: str, method: str = "GET"):
    base = f"http://127.0.0.1:{server['port']}{server.get('base_url', '/')}"
    request = urllib.request.Request(base + path.lstrip("/"), method=method,
                                     headers={"Authorization": f"token {server.get('token', '')}"})
    with urllib.request.urlopen(request, timeout=30) as response:
        body = response.read()
    return json.loads(body) if body else None


def shutdown_other_kernels(kernels: list[OtherKernel] | None = None) -> tuple[list[OtherKernel], str]:
    """Shut down ``kernels`` (default: :func:`other_kernels`) through this kernel's Jupyter server and
    wait until they and their child processes have ended. Returns (the kernels shut down, one line)."""
    import psutil

    kernels = other_kernels() if kernels is None else kernels
    if not kernels:
        return [], "[course] No other course kernel of this Jupyter server runs ROS: nothing to shut down."
    server = this_server()
    if server is None:
        return [], (f"[course] This kernel was not started by a Jupyter server (no jpserver-{os.getppid()}"
                    ".json in its runtime folder): shut the other kernels down where they were started.")
    try:
        listed = {kernel["id"] for kernel in _api(server, "api/kernels") or []}
    except (OSError, ValueError) as error:
        return [], f"[course] The Jupyter server did not answer ({error}): use JupyterLab's Running panel."
    done, skipped, processes = [], [], []
    for kernel in kernels:
        kid = kernel_id(kernel.pid)
        if kid is None or kid not in listed:
            skipped.append(kernel)
            continue
        try:
            tree = [psutil.Process(kernel.pid), *(psutil.Process(pid) for pid in kernel.children)]
        except psutil.Error:
            tree = []
        try:
            _api(server, f"api/kernels/{kid}", method="DELETE")
        except (OSError, ValueError) as error:
            skipped.append(kernel)
            print(f"[course] {kernel.name}: the server refused to shut it down ({error})")
            continue
        done.append(kernel)
        processes += tree
    _gone, alive = psutil.wait_procs(processes, timeout=STOP_WAIT_S)
    return done, _summary(done, skipped, alive)


def shut_down_and_say() -> list[OtherKernel]:
    """``rt.shutdown_other_kernels()``: :func:`shutdown_other_kernels`, its line printed; the kernels
    shut down."""
    done, line = shutdown_other_kernels()
    print(line)
    return done


def _summary(done: list[OtherKernel], skipped: list[OtherKernel], alive: list) -> str:
    children = sum(len(kernel.children) for kernel in done)
    line = "[course] "
    if done:
        many = len(done) > 1
        line += (f"Shut down {len(done)} other course kernel{'s' if many else ''} of this Jupyter server "
                 f"({'; '.join(kernel.name for kernel in done)}): {'their' if many else 'its'} nodes and "
                 f"{children} child process{'' if children == 1 else 'es'} stopped.")
    if alive:
        line += f" Still running after {STOP_WAIT_S:.0f} s: pids {', '.join(str(p.pid) for p in alive)}."
    if skipped:
        line += (f"{' ' if done else ''}Not a kernel this server lists, left alone: "
                 f"{'; '.join(kernel.describe() for kernel in skipped)}.")
    return line
