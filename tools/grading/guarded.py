"""nbgrader's Execute preprocessor, guarded for students' code that misbehaves.

nbgrader already interrupts a cell that runs past ``Execute.timeout`` and records a
``CellTimeoutError``. :class:`GuardedExecute` adds, for each cell:

* the machine's load, when the wall clock cut a cell: a hang and a correct answer slowed by a
  busy machine look the same to it. If the machine was busy while the cell ran (the course's one
  load verdict, :class:`course_helpers.core.machine_load.MachineLoad`), the error says the
  timeout is inconclusive, with the load, and to grade again on a quiet machine; the exercise
  still scores zero, as an inconclusive verdict is never a pass;

* an output limit: past ``max_output_bytes`` the cell's further output is dropped, the
  kernel is interrupted and the cell gets an ``OutputLimitExceeded`` error;
* a dead kernel: the cell gets a ``KernelDied`` error, the kernel is restarted and the cells
  before it run again (test cells left out), so the exercises after it are still graded;
* runaway processes: when an exercise's test cell has run, every process that appeared
  since its solution cell started and is still alive - other than the course's own child
  nodes, which die with the kernel - is killed and the test cell gets a ``RunawayProcesses``
  error. The grading process is a child subreaper (``autograde_one``), so a process that
  detached itself (double fork, new session) is still found among its descendants.

An error in a test cell makes nbgrader score it zero (these go first among the cell's
outputs: nbgrader reads them in order and would take a score printed before them), so each
of these costs only the exercise it happened in, and the error text is the reason shown in
the feedback and the grade table. What happened, the kernels' PIDs and the ROS domains they
held are written as JSON to ``record_path`` for the sweep that follows the run (:mod:`.isolation`),
with the cell being run and each test cell as it starts (the grader shows them as progress).
"""

from __future__ import annotations

import asyncio
import copy
import json
import os
import re

import psutil
from jupyter_core.utils import run_sync
from nbclient.exceptions import DeadKernelError
from nbformat.v4 import new_output
from nbgrader.preprocessors import Execute
from traitlets import Integer, Unicode

from course_helpers.core.domains import SOCKET_PREFIX
from course_helpers.core.machine_load import LoadMeter
from tools.grading.isolation import kill_all

DOMAIN_SOCKET = re.compile(r"^@" + re.escape(SOCKET_PREFIX) + r"(\d+)$")
COURSE_CHILD = "course_helpers.core.child"  # how the course's process layer starts a child
PARENT_ENV = "COURSE_PARENT_PID"  # set by that layer for a child that must die with the kernel
TIMEOUT = "CellTimeoutError"  # the ename of nbgrader's error for a cell cut by Execute.timeout


def _error(ename: str, evalue: str) -> dict:
    return new_output("error", ename=ename, evalue=evalue, traceback=[f"{ename}: {evalue}"])


class GuardedExecute(Execute):
    """Execute with an output limit, kernel revival and a runaway-process check per exercise."""

    max_output_bytes = Integer(1_000_000, help="output of a cell before it is stopped").tag(config=True)
    record_path = Unicode("", help="where to write the run record (JSON); '' for none").tag(config=True)

    def preprocess(self, nb, resources=None, km=None):
        self._record = {"kernels": [], "domains": [], "events": [], "tests_started": []}
        self._dead_reason = ""
        self._before: set[tuple[int, float]] = set()
        self._out_bytes, self._flooded = 0, False
        return super().preprocess(nb, resources, km)

    def _save(self) -> None:
        """Write the record now: a run stopped by the wall clock still leaves what it knew."""
        if self.record_path:
            with open(self.record_path + ".new", "w", encoding="utf-8") as f:
                json.dump(self._record, f, indent=1)
            os.replace(self.record_path + ".new", self.record_path)

    # ------------------------------------------------------------------ per cell
    def preprocess_cell(self, cell, resources, index):
        if cell.cell_type != "code":
            return super().preprocess_cell(cell, resources, index)
        meta = cell.metadata.get("nbgrader", {})
        label = meta.get("grade_id", f"cell {index}")
        if self._dead_reason:
            cell.outputs = [_error("NotRun", self._dead_reason)]
            return cell, self.resources
        # the grader's progress lines: the cell being run, and each test cell as it starts
        self._record["running"] = {"cell": index, "cells": len(self.nb.cells)}
        if meta.get("grade"):
            self._record["tests_started"].append({"test": label, **self._record["running"]})
        self._save()
        if meta.get("solution"):
            self._before = self._descendants()
        self._out_bytes, self._flooded = 0, False
        meter = LoadMeter()
        try:
            cell, _ = super().preprocess_cell(cell, resources, index)
        except DeadKernelError:
            reason = "the kernel died while this cell ran (the process crashed or was killed)"
            cell.outputs.insert(0, _error("KernelDied", reason))
            self._event(label, "kernel died", reason)
            self._revive(index)
            return cell, self.resources
        self._note_kernel()
        self._judge_timeout(cell, label, meter)
        if self._flooded:
            reason = (f"the cell printed more than {self.max_output_bytes} bytes; the rest was dropped "
                      "and the cell was interrupted")
            cell.outputs.insert(0, _error("OutputLimitExceeded", reason))
            self._event(label, "output flood", reason)
        if meta.get("grade") and not meta.get("solution"):
            runaway = self._stop_runaway()
            if runaway:
                reason = (f"the exercise left {len(runaway)} process(es) running, which were killed: "
                          + "; ".join(runaway))
                cell.outputs.insert(0, _error("RunawayProcesses", reason))
                self._event(label, "runaway processes", reason)
        return cell, self.resources

    def output(self, outs, msg, display_id, cell_index):
        if msg["msg_type"] != "error":
            content = msg.get("content", {})
            self._out_bytes += len(content.get("text", "")) + sum(
                len(str(v)) for v in content.get("data", {}).values())
            if self._out_bytes > self.max_output_bytes:
                if not self._flooded:
                    self._flooded = True
                    asyncio.ensure_future(self.km.interrupt_kernel())
                return None
        return super().output(outs, msg, display_id, cell_index)

    def _judge_timeout(self, cell, label: str, meter: LoadMeter) -> None:
        """If the wall clock cut the cell while the machine was busy, say so in its error."""
        cut = [o for o in cell.outputs if o.get("output_type") == "error" and o.get("ename") == TIMEOUT]
        if not cut:
            return
        load = meter.finish()
        if not load.busy:
            return
        cut[0].evalue = busy_timeout(cut[0].evalue, load)
        cut[0].traceback = [f"{TIMEOUT}: {cut[0].evalue}"]
        self._event(label, "timeout on a busy machine", cut[0].evalue)

    # ------------------------------------------------------------------ helpers
    def _event(self, cell: str, kind: str, detail: str) -> None:
        self._record["events"].append({"cell": cell, "kind": kind, "detail": detail})
        self._save()

    def _kernel_pid(self) -> int | None:
        return getattr(getattr(self.km, "provisioner", None), "pid", None)

    def _note_kernel(self) -> None:
        """Remember the kernel's PID and the domains it holds (its reservation sockets)."""
        pid = self._kernel_pid()
        if pid is None:
            return
        known = (list(self._record["kernels"]), list(self._record["domains"]))
        if pid not in self._record["kernels"]:
            self._record["kernels"].append(pid)
        try:
            for connection in psutil.Process(pid).net_connections(kind="unix"):
                match = DOMAIN_SOCKET.match(connection.laddr or "")
                if match and int(match.group(1)) not in self._record["domains"]:
                    self._record["domains"].append(int(match.group(1)))
        except psutil.Error:
            pass
        if known != (self._record["kernels"], self._record["domains"]):
            self._save()

    @staticmethod
    def _descendants() -> set[tuple[int, float]]:
        found = set()
        for proc in psutil.Process().children(recursive=True):
            try:
                found.add((proc.pid, proc.create_time()))
            except psutil.Error:
                pass
        return found

    def _stop_runaway(self) -> list[str]:
        """Kill the processes started since the exercise began that still run; describe them."""
        kernel = self._kernel_pid()
        runaway = []
        for pid, started in sorted(self._descendants() - self._before):
            try:
                proc = psutil.Process(pid)
                if proc.create_time() != started or pid == kernel or proc.status() == psutil.STATUS_ZOMBIE:
                    continue
                if proc.ppid() == kernel and (proc.environ().get(PARENT_ENV) == str(kernel)
                                              or COURSE_CHILD in " ".join(proc.cmdline())):
                    continue  # started by the course's process layer: it stops with the kernel
                runaway.append(proc)
            except psutil.Error:
                continue
        return kill_all(runaway)

    def _revive(self, index: int) -> None:
        """Restart the dead kernel and run the cells before ``index`` again (not the test cells)."""
        try:
            run_sync(self.km.restart_kernel)(now=True)
            run_sync(self.kc.wait_for_ready)(timeout=self.startup_timeout)
            for j, earlier in enumerate(self.nb.cells[:index]):
                if earlier.cell_type == "code" and not earlier.metadata.get("nbgrader", {}).get("grade"):
                    super().preprocess_cell(copy.deepcopy(earlier), self.resources, j)
            self._note_kernel()
            self._event(f"cell {index}", "kernel restarted", f"cells 0-{index - 1} ran again")
        except Exception as exc:  # the kernel cannot be brought back: the rest is not run
            self._dead_reason = f"not run: the kernel died in cell {index} and could not be restarted ({exc})"
            self._event(f"cell {index}", "kernel lost", self._dead_reason)


def busy_timeout(evalue: str, load) -> str:
    """A timeout's message when the machine was busy: inconclusive, the load, and what to do."""
    return (f"{evalue}. Inconclusive: this machine was busy while it ran ({load.reading()}), so the "
            "cell may have been slowed, not hung; grade it again when the machine is quiet")
