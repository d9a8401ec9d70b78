"""Drive a real Jupyter kernel from tests, as JupyterLab or nbval would."""

from __future__ import annotations

import os
import subprocess
import tempfile
import time

from tools.kernels import PrivateSocketKernelManager


class KernelSession:
    """A started IPython kernel of this venv, with helpers to run cells and read outputs."""

    def __init__(self, cwd: str, env: dict | None = None):
        self.stderr_file = tempfile.TemporaryFile(mode="w+")
        extra = dict(env or {})
        env = dict(os.environ)
        env.pop("ROS_DOMAIN_ID", None)  # the kernel reserves its own, unless the test sets one
        env.update(extra)
        self.km = PrivateSocketKernelManager(kernel_name="python3")  # no port to collide on
        self.km.start_kernel(cwd=cwd, env=env, stderr=self.stderr_file,
                             stdout=subprocess.DEVNULL,
                             extra_arguments=[], independent=False)
        self.process = self.km.provisioner.process
        self.client = self.km.client()
        self.client.start_channels()
        self.client.wait_for_ready(timeout=60)
        self.displays: dict[str, dict] = {}  # display id -> its latest data (consoles update theirs)
        self.traceback: list[str] = []  # the last cell's error as a frontend shows it, line by line
        self.execution_count: int | None = None  # the In [N] number of the last cell run

    def run(self, code: str, timeout: float = 60, interrupt_after: float | None = None):
        """Execute a cell; return (outputs, error) where outputs are stream/display texts.

        Displays with an ID (node consoles) are also kept in ``displays`` with their latest data,
        whichever cell was running when they changed. The error's traceback lines are kept in
        ``traceback``, the cell's execution count in ``execution_count``.
        """
        msg_id = self.client.execute(code)
        outputs, error = [], None
        self.traceback, self.execution_count = [], None
        deadline = time.monotonic() + timeout
        interrupt_at = time.monotonic() + interrupt_after if interrupt_after else None
        while True:
            if interrupt_at and time.monotonic() > interrupt_at:
                self.km.interrupt_kernel()
                interrupt_at = None
            if time.monotonic() > deadline:
                raise TimeoutError(f"cell did not finish in {timeout} s: {code[:60]!r}")
            try:
                msg = self.client.get_iopub_msg(timeout=0.2)
            except Exception:
                continue
            kind, content = msg["msg_type"], msg["content"]
            if kind in ("display_data", "update_display_data"):
                display_id = content.get("transient", {}).get("display_id")
                if display_id:  # a display that later updates (a node console): keep its latest data
                    self.displays[display_id] = content["data"]
            if msg["parent_header"].get("msg_id") != msg_id:
                continue
            if kind == "stream":
                outputs.append(content["text"])
            elif kind in ("display_data", "execute_result"):
                outputs.append(content["data"].get("text/plain", ""))
            elif kind == "error":
                error = content["ename"]
                self.traceback = list(content["traceback"])
            elif kind == "execute_input":
                self.execution_count = content["execution_count"]
            elif kind == "status" and content["execution_state"] == "idle":
                return "".join(outputs), error

    def shutdown(self) -> tuple[int | None, str]:
        """Ask the kernel to shut down (as the Lab's 'Shut Down Kernel' does); (exit code, stderr)."""
        if self.process.poll() is None:
            self.client.stop_channels()
            self.km.shutdown_kernel(now=False)
        code = self.process.wait(timeout=30)
        self.stderr_file.seek(0)
        return code, self.stderr_file.read()

