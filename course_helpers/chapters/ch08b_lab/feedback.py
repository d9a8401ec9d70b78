"""What the QoS lab's panel says around a run: the machine before it, the progress during it, the
machine after it.

* **Before a run** (:meth:`RunFeedback.check_machine`): a short reading of the machine
  (:class:`course_helpers.core.machine_load.LoadMeter`, :data:`PRE_RUN_S`) and this user's other
  course kernels (:mod:`course_helpers.core.other_kernels`, machine-wide). On a busy machine, or with
  other course kernels running, the panel says so before the run starts, with what it costs, and a
  button that shuts this user's other kernels of this Jupyter server down
  (:func:`course_helpers.core.kernel_shutdown.shutdown_other_kernels`).
* **During a run** (:meth:`RunFeedback.run_started`, :meth:`~RunFeedback.sample`): a progress line,
  rewritten every :data:`TICK_S` by a thread of its own whatever the run does: the seconds since the
  run started, then the samples sent and delivered so far (the publisher's process may take a while
  to start on a busy machine, and the line shows that time passing).
* **After the runs** (:func:`machine_line`): how busy the machine was during them.
"""

from __future__ import annotations

import html
import threading
import time

import ipywidgets as widgets

from course_helpers.core.kernel_shutdown import shutdown_other_kernels
from course_helpers.core.machine_load import LoadMeter, MachineLoad
from course_helpers.core.other_kernels import other_kernels

PRE_RUN_S = 0.5  # the reading before a run: long enough to see other processes' CPU, short to wait
TICK_S = 0.5  # the progress line is rewritten this often


class RunFeedback:
    """The panel's lines around runs: ``busy_box`` (before a run) and ``progress`` (during it)."""

    def __init__(self):
        self.progress = widgets.HTML()
        self.busy_text = widgets.HTML()
        self.shutdown_button = widgets.Button(description="Shut down my other kernels", icon="power-off",
                                              button_style="warning", layout=widgets.Layout(width="auto"),
                                              tooltip="rt.shutdown_other_kernels(): this user's other "
                                                      "course kernels of this Jupyter server")
        self.shutdown_said = widgets.HTML()
        self.shutdown_button.on_click(self._shut_down)
        self.busy_box = widgets.VBox([self.busy_text,
                                      widgets.HBox([self.shutdown_button, self.shutdown_said])])
        self.busy_box.layout.display = "none"
        self.before: MachineLoad | None = None  # the last reading before a run
        self.ticks = 0  # progress lines written during the last run
        self._run: tuple | None = None  # (number, total, label, started) of the run in progress
        self._snap = None
        self._lock = threading.Lock()
        self._ticker: threading.Thread | None = None
        self._stop = threading.Event()

    # ------------------------------------------------------------------ before a run
    def check_machine(self, duration_s: float, seconds: float = PRE_RUN_S) -> MachineLoad:
        """Read the machine for ``seconds``; on a busy machine, or with other course kernels, say so in
        the panel before the run (of ``duration_s`` seconds of sending) starts. Returns the reading."""
        self.progress.value = _line("Looking at the machine before the run ...")
        meter = LoadMeter()
        time.sleep(seconds)
        load = meter.finish()
        self.before = load
        if not (load.busy or load.kernels or load.children):
            self.busy_box.layout.display = "none"
            return load
        names = "; ".join(kernel.describe() for kernel in other_kernels(machine_wide=True))
        state = "busy" if load.busy else "not busy yet"
        course = load.course_processes()
        verb = "is" if len(load.kernels) + len(load.children) == 1 else "are"
        text = (f"Before this run, this machine is {state}: {load.reading()}"
                + (f"; {course} {verb} running ({names})" if course else "") + ". "
                f"What it costs: the publisher's process starts, and reliable's repairs are sent, only when "
                f"they get a CPU, so this run can take many times its {duration_s:g} s of sending, and its "
                f"timing shows the load rather than the QoS. To measure a quiet machine, {load.advice()}.")
        self.busy_text.value = f"<div class='qos-lab-busy' style='color:#8a5a00'>{html.escape(text)}</div>"
        self.shutdown_button.layout.display = "" if load.kernels else "none"
        self.shutdown_button.disabled = False
        self.shutdown_said.value = ""
        self.busy_box.layout.display = ""
        return load

    def _shut_down(self, _button=None) -> None:
        self.shutdown_button.disabled = True
        self.shutdown_said.value = "<i>shutting them down ...</i>"
        _done, line = shutdown_other_kernels()
        self.shutdown_said.value = f"<span class='course-shutdown-result'>{html.escape(line)}</span>"

    # ------------------------------------------------------------------ during a run
    def run_started(self, number: int, total: int, label: str) -> None:
        """A run begins: the progress line starts counting its seconds."""
        with self._lock:
            self._run, self._snap = (number, total, label, time.monotonic()), None
        self.ticks = 0
        if self._ticker is None or not self._ticker.is_alive():
            self._stop = threading.Event()
            self._ticker = threading.Thread(target=self._tick, args=(self._stop,), name="qos-lab-progress",
                                            daemon=True)
            self._ticker.start()
        self._write()

    def sample(self, snap) -> None:
        """The run's latest :class:`.results.Snapshot` (the next tick shows it)."""
        with self._lock:
            self._snap = snap

    def finished(self) -> None:
        """The runs ended: the ticker stops and the line says how long the last one took."""
        self._stop.set()
        with self._lock:
            run, snap, self._run = self._run, self._snap, None
        if run is not None:
            self.progress.value = _line(_progress_text(run, snap, time.monotonic() - run[3], ended=True))

    def _tick(self, stop: threading.Event) -> None:
        while not stop.wait(TICK_S):
            self._write()

    def _write(self) -> None:
        with self._lock:
            run, snap = self._run, self._snap
        if run is not None:
            self.progress.value = _line(_progress_text(run, snap, time.monotonic() - run[3]))
            self.ticks += 1


def _progress_text(run: tuple, snap, elapsed: float, ended: bool = False) -> str:
    number, total, label, _started = run
    head = f"Run {number}/{total} ({label}): {elapsed:.1f} s {'in all' if ended else 'so far'}"
    if snap is None:
        return f"{head}, starting the publisher's process (nothing sent yet)"
    return (f"{head}; {snap.published} sent and {snap.delivered} delivered in the {snap.t:.1f} s since "
            "sending began")


def _line(text: str) -> str:
    return f"<div class='qos-lab-progress' style='color:#1f4e79'>{html.escape(text)}</div>"


def machine_line(runs) -> str:
    """The busiest of ``runs``' machine loads in one line ('' when it was quiet and alone)."""
    loads = [r.machine for r in runs if r.machine is not None]
    if not loads:
        return ""
    load = max(loads, key=lambda m: (m.busy, m.others_cores))
    if not load.busy and not (load.kernels or load.children):
        return ""
    return load.describe()


def machine_note(runs) -> str:
    """The panel's note after ``runs``: how busy the machine was ('' when it was quiet and alone)."""
    line = machine_line(runs)
    busy = any(r.machine is not None and r.machine.busy for r in runs)
    colour = "#8a5a00" if busy else "#555555"
    return f'<div class="qos-lab-machine" style="color:{colour}">{html.escape(line)}</div>' if line else ""
