"""Drive a real Jupyter kernel from tests, as JupyterLab or nbval would."""

from __future__ import annotations

import os
import subprocess
import tempfile
import time

from jupyter_client import KernelManager


class KernelSession:
    """A started IPython kernel of this venv, with helpers to run cells and read outputs."""

    def __init__(self, cwd: str, env: dict | None = None):
        self.stderr_file = tempfile.TemporaryFile(mode="w+")
        extra = dict(env or {})
        env = dict(os.environ)
        env.pop("ROS_DOMAIN_ID", None)  # the kernel reserves its own, unless the test sets one
        env.update(extra)
        self.km = KernelManager(kernel_name="python3")
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
        self.display_cells: dict[str, str] = {}  # display id -> msg_id of the cell it was created under
        self.cell_display_ids: list[str] = []  # the displays with an ID that the last cell created
        self.cell_outputs: list[tuple[str, str]] = []  # the last cell's outputs: (kind, display id or "")
        self.cell_streams = ""  # what the last cell printed (its stream outputs only)
        self.cell_msg_id = ""  # the msg_id of the last cell's execute request

    def run(self, code: str, timeout: float = 60, interrupt_after: float | None = None):
        """Execute a cell; return (outputs, error) where outputs are stream/display texts.

        Displays with an ID (node consoles) are also kept in ``displays`` with their latest data,
        whichever cell was running when they changed (``display_cells`` says under which cell each
        was created); ``cell_display_ids`` lists the ones this cell created, in order, and
        ``cell_streams`` is its printed text alone; ``cell_outputs`` lists its outputs in order.
        The error's traceback lines are kept in ``traceback``, the cell's execution count in
        ``execution_count``.
        """
        msg_id = self.cell_msg_id = self.client.execute(code)
        outputs, error = [], None
        self.traceback, self.execution_count = [], None
        self.cell_display_ids, self.cell_streams, self.cell_outputs = [], "", []
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
            self._keep_display(msg)
            if msg["parent_header"].get("msg_id") != msg_id:
                continue
            if kind in ("stream", "display_data", "execute_result"):
                self.cell_outputs.append((kind, content.get("transient", {}).get("display_id", "")))
            if kind == "stream":
                outputs.append(content["text"])
                self.cell_streams += content["text"]
            elif kind in ("display_data", "execute_result"):
                outputs.append(content["data"].get("text/plain", ""))
                if content.get("transient", {}).get("display_id"):
                    self.cell_display_ids.append(content["transient"]["display_id"])
            elif kind == "error":
                error = content["ename"]
                self.traceback = list(content["traceback"])
            elif kind == "execute_input":
                self.execution_count = content["execution_count"]
            elif kind == "status" and content["execution_state"] == "idle":
                return "".join(outputs), error

    def listen(self, seconds: float) -> None:
        """Read what the kernel sends for ``seconds`` while no cell runs (late console lines)."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            try:
                self._keep_display(self.client.get_iopub_msg(timeout=0.1))
            except Exception:
                continue

    def _keep_display(self, msg: dict) -> None:
        """Keep the latest data of a display with an ID (a node console), and its cell."""
        kind, content = msg["msg_type"], msg["content"]
        display_id = content.get("transient", {}).get("display_id")
        if kind in ("display_data", "update_display_data") and display_id:
            self.displays[display_id] = content["data"]
            if kind == "display_data":
                self.display_cells[display_id] = msg["parent_header"].get("msg_id")

    def shutdown(self) -> tuple[int | None, str]:
        """Ask the kernel to shut down (as the Lab's 'Shut Down Kernel' does); (exit code, stderr)."""
        if self.process.poll() is None:
            self.client.stop_channels()
            self.km.shutdown_kernel(now=False)
        code = self.process.wait(timeout=30)
        self.stderr_file.seek(0)
        return code, self.stderr_file.read()

