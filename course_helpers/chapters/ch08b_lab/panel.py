"""The QoS lab panel: widgets over ``run_experiment``.

``lab = qos_lab()`` shows a panel: the QoS of both ends (reliability, durability,
history, depth), the load (rate, payload size, the subscriber's processing time,
transport, duration, late joiner), Run / Stop / Compare buttons, one-click preset
scenarios, a plot that follows a run live and a results table that gains one row
per run. The measuring is done by :func:`course_helpers.chapters.ch08b_lab.run.run_experiment`
in a background thread, so the notebook's other cells keep running meanwhile; the
plot is drawn by :class:`course_helpers.chapters.ch08b_lab.plots.ResultsFigure`.

In a notebook the panel is shown with a static record (``course_helpers.notebook.records``):
the results table and a picture of the final plot, replaced whenever runs finish, so a saved
copy of the notebook shows what the panel measured.

Settings the engine would refuse are prevented (depth is disabled with KEEP_ALL,
sliders are bounded) or explained in the panel, never shown as a traceback.
Running the cell again closes the previous panel and its experiment first.
"""

from __future__ import annotations

import html
import threading
import time

import ipywidgets as widgets

from course_helpers.chapters.ch08b_lab.config import (
    MAX_DEPTH,
    MAX_LOSS_PERCENT,
    MAX_PROCESSING_MS,
    PRESETS,
    ExperimentConfig,
    preset,
)
from course_helpers.chapters.ch08b_lab.feedback import RunFeedback, machine_line, machine_note
from course_helpers.chapters.ch08b_lab.link import link_unavailable_reason
from course_helpers.chapters.ch08b_lab.plots import ResultsFigure, draw_still
from course_helpers.chapters.ch08b_lab.results import ExperimentResult
from course_helpers.chapters.ch08b_lab.run import run_experiment
from course_helpers.chapters.ch08b_lab.table import results_table_html
from course_helpers.core.errors import CourseError
from course_helpers.core.units import format_bytes

RATES_HZ = (1, 2, 5, 10, 20, 50, 100, 200, 400, 500, 1000, 2000, 5000)
PAYLOADS = (16, 256, 1024, 4096, 16384, 65536, 262144, 2**20, 2 * 2**20, 4 * 2**20)
MAX_FRAME_HZ = 8.0  # the live plot redraws at most this often
RECORD_TITLE = "QoS lab"
_active: QoSLab | None = None


def qos_lab() -> QoSLab:
    """Show a new lab panel, closing the one a previous run of the cell made."""
    global _active
    if _active is not None:
        _active.close()
    _active = QoSLab()
    return _active


class QoSLab:
    """The panel. ``lab.results`` holds every finished :class:`ExperimentResult`."""

    def __init__(self):
        self.results: list[ExperimentResult] = []
        self.config_b: ExperimentConfig | None = None
        self.pair: list[ExperimentConfig] | None = None  # a two-run preset, while the panel shows it
        self.frame_hz: float | None = None  # live-plot refresh rate of the last run
        self.frame_seconds = 0.0  # how long the last frame took to draw
        self.live_frames = 0  # live frames shown while the last start()'s runs were in progress
        self.draw_cpu_seconds = 0.0  # CPU time the frames of the last start() took to draw
        self._thread: threading.Thread | None = None
        self._busy = False
        self._changed_while_busy = False  # a setting moved during a run: announced when it ends
        self._stop = threading.Event()
        self._figure = ResultsFigure()
        self._last_frame = 0.0
        self.record = None  # the static record, once the panel is displayed in a notebook
        self._last_runs: list[ExperimentResult] = []  # the runs of the last start(), as the plot shows them
        self._recorded: tuple = ()  # what the record shows now (so an update is made once)
        self._build()
        self._validate(announce=True)
        self._show_frame([])

    # ------------------------------------------------------------------ layout
    def _build(self) -> None:
        w = widgets
        wide = w.Layout(width="330px")
        style = {"description_width": "110px"}
        self.reliability = w.ToggleButtons(options=[("reliable", "reliable"), ("best effort", "best_effort")],
                                           description="reliability", style=style)
        self.durability = w.ToggleButtons(options=[("volatile", "volatile"),
                                                   ("transient local", "transient_local")],
                                          description="durability", style=style)
        self.history = w.ToggleButtons(options=[("keep last", "keep_last"), ("keep all", "keep_all")],
                                       description="history", style=style)
        self.depth = w.BoundedIntText(value=10, min=1, max=MAX_DEPTH, description="depth",
                                      style=style, layout=w.Layout(width="200px"))
        self.rate = w.SelectionSlider(options=[(f"{r} Hz", r) for r in RATES_HZ], value=100,
                                      description="rate", style=style, layout=wide)
        self.payload = w.SelectionSlider(options=[(format_bytes(b), b) for b in PAYLOADS],
                                         value=1024, description="payload", style=style, layout=wide)
        self.processing = w.FloatSlider(value=0.0, min=0.0, max=MAX_PROCESSING_MS, step=1.0,
                                        description="processing (ms)", readout_format=".0f",
                                        style=style, layout=wide)
        self.link_reason = link_unavailable_reason()  # None where the lossy link can be made
        transports = [("shared memory", "shm"), ("UDP", "udp")]
        self.transport = w.ToggleButtons(options=transports + ([] if self.link_reason else
                                                               [("lossy link", "lossy_link")]),
                                         description="transport", style=style)
        self.loss = w.IntSlider(value=0, min=0, max=MAX_LOSS_PERCENT, description="link loss (%)",
                                style=style, layout=wide, disabled=True)
        self.link_note = w.HTML("" if self.link_reason is None else
                                f"<small>lossy link unavailable: {html.escape(self.link_reason)}</small>")
        self.duration = w.FloatSlider(value=1.0, min=0.1, max=10.0, step=0.05, description="duration (s)",
                                      readout_format=".2f", style=style, layout=wide)
        self.late_joiner = w.Checkbox(value=False, description="late joiner (subscribe after sending)",
                                      indent=False)
        for control in (self.reliability, self.durability, self.history, self.transport):
            control.style.button_width = "125px"

        self.run_button = w.Button(description="Run", button_style="primary", icon="play")
        self.stop_button = w.Button(description="Stop", button_style="danger", icon="stop", disabled=True)
        self.compare_button = w.Button(description="Compare", button_style="info", icon="columns",
                                       tooltip="run configuration B, then the panel's settings, and "
                                               "overlay them", disabled=True)
        self.keep_b_button = w.Button(description="Keep as B", icon="bookmark",
                                      tooltip="remember the panel's settings as configuration B")
        self.clear_button = w.Button(description="Clear table", icon="trash")
        self.run_button.on_click(self._guard(self._on_run))
        self.stop_button.on_click(self._guard(self._on_stop))
        self.compare_button.on_click(self._guard(self._on_compare))
        self.keep_b_button.on_click(self._guard(self._on_keep_b))
        self.clear_button.on_click(self._guard(self._on_clear))

        self.preset_buttons = []
        self._link_presets = set()  # tooltips of the presets that need the (unavailable) lossy link
        for name, entry in PRESETS.items():
            needs_link = any(c.transport == "lossy_link" for c in entry["configs"])
            button = w.Button(description=name, tooltip=entry["what"], layout=w.Layout(width="auto"),
                              disabled=bool(needs_link and self.link_reason))
            if button.disabled:
                self._link_presets.add(entry["what"])
            button.on_click(self._guard(lambda _b, name=name: self._load_preset(name)))
            self.preset_buttons.append(button)

        self.b_label = w.HTML()
        self.status = w.HTML()
        self.machine_note = w.HTML()  # how busy the machine was during the last runs
        self.feedback = RunFeedback()  # the machine before a run, the progress line during it
        self.image = w.Image(format="png", layout=w.Layout(width="100%", max_width="980px"))
        self.table = w.HTML()
        for control in self._config_controls():
            control.observe(self._guard(lambda _change: self._validate(announce=True)), names="value")
        self._refresh_b_label()
        self._refresh_table()

        title = w.HTML("<b>QoS lab</b>: the publisher runs in a child process, the subscriber in this "
                       "kernel; samples cross a real Fast DDS transport. Nothing is simulated.")
        qos_box = w.VBox([w.HTML("<b>QoS</b> (both ends)"), self.reliability, self.durability,
                          self.history, self.depth])
        load_box = w.VBox([w.HTML("<b>Load</b>"), self.rate, self.payload, self.processing,
                           self.duration, self.transport, self.loss, self.link_note, self.late_joiner])
        self.widget = w.VBox([
            title,
            w.HBox([w.HTML("presets:"), *self.preset_buttons], layout=w.Layout(flex_flow="row wrap")),
            w.HBox([qos_box, load_box], layout=w.Layout(grid_gap="24px")),
            w.HBox([self.run_button, self.stop_button, self.compare_button, self.keep_b_button,
                    self.clear_button]),
            self.b_label, self.status, self.feedback.busy_box, self.feedback.progress, self.machine_note,
            self.image, self.table,
        ])
        self.widget.add_class("qos-lab")

    def _config_controls(self):
        return (self.reliability, self.durability, self.history, self.depth, self.rate, self.payload,
                self.processing, self.transport, self.loss, self.duration, self.late_joiner)

    def _ipython_display_(self):
        from course_helpers.notebook.records import show_with_record

        text, body = self._record_body()
        self.record = show_with_record(self.widget, RECORD_TITLE, text, body)
        self._recorded = ()

    def update_record(self) -> None:
        """Replace the static record with the results table and a picture of the last runs' plot.

        Called when runs finish and by :meth:`wait`; does nothing before the panel is displayed
        or when the record already shows these runs.
        """
        key = (len(self.results), tuple(id(r) for r in self._last_runs))
        if self.record is None or key == self._recorded:
            return
        self._recorded = key
        text, body = self._record_body()
        figure = draw_still(self._last_runs) if self._last_runs else None
        self.record.update(text, html_body=body, figure=figure)

    def _record_body(self) -> tuple[str, str]:
        """The record as plain text (one line per run) and HTML (the results table)."""
        if not self.results:
            text = "no runs yet: each run adds a row to the table"
        else:
            text = "\n".join(f"{number}. {result.summary()}" for number, result in enumerate(self.results, 1))
        machine = machine_line(self._last_runs)
        if machine:
            text += "\n" + machine
        body = (f"<p><b>QoS lab</b>: {len(self.results)} run(s) in this session. The plot below shows "
                "the last Run or Compare.</p>" + (f"<p>{html.escape(machine)}</p>" if machine else "")
                + results_table_html(self.results))
        return text, body

    # ------------------------------------------------------------------ configuration
    def config(self) -> ExperimentConfig:
        """The panel's settings as an :class:`ExperimentConfig` (raises CourseError if not allowed)."""
        keep_all = self.history.value == "keep_all"
        return ExperimentConfig(
            reliability=self.reliability.value, durability=self.durability.value,
            history=self.history.value, depth=None if keep_all else int(self.depth.value),
            rate_hz=float(self.rate.value), payload_bytes=int(self.payload.value),
            processing_ms=float(self.processing.value), transport=self.transport.value,
            duration_s=round(float(self.duration.value), 3), late_joiner=bool(self.late_joiner.value),
            loss_percent=int(self.loss.value) if self.transport.value == "lossy_link" else 0)

    def set_config(self, config: ExperimentConfig) -> None:
        """Put ``config`` into the panel's widgets."""
        self.reliability.value = config.reliability
        self.durability.value = config.durability
        self.history.value = config.history
        if config.depth is not None:
            self.depth.value = config.depth
        self.rate.value = min(RATES_HZ, key=lambda r: abs(r - config.rate_hz))
        self.payload.value = min(PAYLOADS, key=lambda b: abs(b - config.payload_bytes))
        self.processing.value = config.processing_ms
        self.transport.value = config.transport
        self.loss.value = config.loss_percent
        self.duration.value = config.duration_s
        self.late_joiner.value = config.late_joiner

    def _validate(self, announce: bool = False) -> ExperimentConfig | None:
        """Enable what makes sense for the current settings; explain what does not.

        ``announce`` also writes 'Ready: ...' in the status line.
        """
        self.depth.disabled = self.history.value == "keep_all"
        self.depth.description = "depth (unused)" if self.depth.disabled else "depth"
        self.loss.disabled = self.transport.value != "lossy_link"
        busy = self.running
        try:
            config = self.config()
        except CourseError as error:
            self.run_button.disabled = self.compare_button.disabled = True
            self.keep_b_button.disabled = True
            self._set_status(f"These settings cannot run: {error}", "warning")
            return None
        if self.pair is not None and not _same_settings(config, self.pair[-1]):
            self.pair = None  # the panel no longer shows the preset: Run runs what it shows
        self.run_button.description = "Run both" if self.pair else "Run"
        self.run_button.tooltip = ("run the preset's two configurations, one after the other" if self.pair
                                   else "run the panel's settings")
        self.run_button.disabled = busy
        self.compare_button.disabled = busy or self.config_b is None
        self.keep_b_button.disabled = False
        if announce and busy:
            self._changed_while_busy = True
        if announce and not busy:
            self._set_status(f"Ready: {html.escape(config.describe())} "
                             f"({config.count} samples).", "info", escape=False)
        return config

    # ------------------------------------------------------------------ buttons
    def _guard(self, handler):
        """Wrap a widget callback so an error shows in the panel, not as a traceback."""
        def call(*args):
            try:
                handler(*args)
            except CourseError as error:
                self._set_status(str(error), "warning")
            except Exception as error:  # a widget callback must never print a traceback
                self._set_status(f"{type(error).__name__}: {error}", "error")
        return call

    def _on_run(self, _button=None) -> None:
        config = self._validate()
        if config is not None:
            self.start(list(self.pair) if self.pair else [config])  # "Run both" after a two-run preset

    def _on_compare(self, _button=None) -> None:
        config = self._validate()
        if config is None:
            return
        if self.config_b is None:
            self._set_status("No configuration B yet: load a two-run preset, or press 'Keep as B'.",
                             "warning")
            return
        self.start([self.config_b, config])

    def _on_stop(self, _button=None) -> None:
        self._stop.set()
        self._set_status("Stopping...", "info")

    def _on_keep_b(self, _button=None) -> None:
        config = self._validate()
        if config is not None:
            self.config_b = config
            self._refresh_b_label()
            self._validate()
            self._set_status(f"Kept as B: {config.describe()}. Change the panel, then press Compare.", "info")

    def _on_clear(self, _button=None) -> None:
        self.results.clear()
        self._last_runs = []
        self._refresh_table()
        self.update_record()

    def _load_preset(self, name: str) -> None:
        if self.running:
            self._set_status("Stop the running experiment before loading a preset.", "warning")
            return
        configs = preset(name)
        self.pair = None
        self.config_b = configs[0] if len(configs) == 2 else None
        self._refresh_b_label()
        self.set_config(configs[-1])
        self.pair = configs if len(configs) == 2 else None
        self._validate()
        what = html.escape(PRESETS[name]["what"])
        if self.pair:
            first, second = (html.escape(c.describe()) for c in self.pair)
            action = (f"Press <b>Run both</b> to run <i>{first}</i>, then <i>{second}</i> (shown in the "
                      "panel), overlaid. Change a setting and <b>Run</b> runs the panel alone.")
        else:
            action = "Press <b>Run</b>."
        self._set_status(f"Preset <b>{html.escape(name)}</b>: {what} {action}", "info", escape=False)

    # ------------------------------------------------------------------ running
    @property
    def running(self) -> bool:
        """True while an experiment runs."""
        return self._busy

    def start(self, configs: list[ExperimentConfig]) -> None:
        """Run ``configs`` one after the other in a background thread (what Run and Compare do)."""
        if self.running:
            raise CourseError("an experiment is already running: press Stop first")
        self._stop = threading.Event()
        self._busy = True
        self.live_frames, self.draw_cpu_seconds = 0, 0.0
        self._thread = threading.Thread(target=self._work, args=(list(configs), self._stop),
                                        name="qos-lab", daemon=True)
        self.run_button.disabled = self.compare_button.disabled = True
        self.stop_button.disabled = False
        for button in self.preset_buttons:
            button.disabled = True
        self._thread.start()

    def wait(self, timeout: float = 60.0) -> bool:
        """Wait until the running experiment ends (then the record shows its runs); True if it did."""
        if self._thread is not None:
            self._thread.join(timeout)
        done = not (self._thread is not None and self._thread.is_alive())
        if done:
            self.update_record()
        return done

    def _work(self, configs, stop: threading.Event) -> None:
        finished: list[ExperimentResult] = []
        frames: list[list[float]] = []  # per run: when each live frame was shown
        try:
            self.machine_note.value = ""
            self.feedback.check_machine(sum(c.duration_s for c in configs))
            for number, config in enumerate(configs, 1):
                if stop.is_set():
                    break
                label = config.describe()
                self._set_status(f"Running {number}/{len(configs)}: {html.escape(label)} ... "
                                 "(the publisher's process starts, then the samples flow; the line "
                                 "below counts)", "info", escape=False)
                self.feedback.run_started(number, len(configs), label)
                live: list = []
                frames.append([])
                expect = (config.duration_s * 1.2 + 0.5, config.count)  # axes sized for the whole run

                def progress(snap, live=live, label=label, shown=frames[-1], number=number, expect=expect):
                    live.append(snap)
                    self.feedback.sample(snap)
                    if self._show_frame([*finished, (label, live)], expect=expect):
                        shown.append(time.monotonic())
                        self._set_status(
                            f"Running {number}/{len(configs)}: {label} | {snap.t:.1f} s: {snap.published} "
                            f"sent, {snap.delivered} delivered, lost {snap.lost_by_sequence} (gaps) / "
                            f"{snap.lost_events} (events), {snap.publish_errors} publish errors", "info")

                result = run_experiment(config, progress=progress, stop_event=stop, progress_period_s=0.02)
                finished.append(result)
                self.results.append(result)
                self._refresh_table()
                self._show_frame(finished, force=True)
            self._last_runs = list(finished)
            self.frame_hz = _frame_rate(frames)
            self.live_frames = sum(len(times) for times in frames)
            lines = "<br>".join(html.escape(r.summary()) for r in finished)
            unfinished = [str(n) for n, r in enumerate(finished, 1) if r.in_flight]
            if stop.is_set():
                headline = "Stopped."
            elif unfinished:
                which = f"run {unfinished[0]}" if len(unfinished) == 1 else "runs " + " and ".join(unfinished)
                headline = (f"Done, but {which} did NOT FINISH: samples were still in flight, not lost, so "
                            "a delivered count there is no result to compare. Run it again.")
            else:
                headline = "Done."
            self._set_status(f"{headline} {lines}", "warning" if unfinished else "info", escape=False)
            self.machine_note.value = machine_note(finished)
            self.update_record()
        except CourseError as error:
            self._set_status(str(error), "warning")
        except Exception as error:  # shown in the panel; the kernel and the panel keep working
            self._set_status(f"The experiment failed: {type(error).__name__}: {error}", "error")
        finally:
            self.feedback.finished()
            self._busy = False
            self.stop_button.disabled = True
            for button in self.preset_buttons:
                button.disabled = button.tooltip in self._link_presets  # the lossy link is unavailable
            changed, self._changed_while_busy = self._changed_while_busy, False
            self._validate(announce=changed)  # the panel's new settings replace the run's summary

    def close(self) -> None:
        """Stop a running experiment (its child process ends) and close the widgets."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        for child in _all_widgets(self.widget):
            child.close()

    # ------------------------------------------------------------------ display
    def _show_frame(self, runs, force: bool = False, expect=None) -> bool:
        """Draw a live frame (at most MAX_FRAME_HZ a second); ``force``: a final frame, fitted."""
        now = time.monotonic()
        if not force and now - self._last_frame < 1.0 / MAX_FRAME_HZ:
            return False
        self._last_frame = now
        cpu = time.thread_time()
        self.image.value = self._figure.frame(runs, fit=force, expect=expect)
        self.draw_cpu_seconds += time.thread_time() - cpu
        self.frame_seconds = time.monotonic() - now
        return True

    def _set_status(self, text: str, kind: str, escape: bool = True) -> None:
        colour = {"info": "#1f4e79", "warning": "#8a5a00", "error": "#a11"}[kind]
        body = html.escape(text) if escape else text
        self.status.value = f'<div class="qos-lab-status" style="color:{colour}">{body}</div>'

    def _refresh_b_label(self) -> None:
        text = html.escape(self.config_b.describe()) if self.config_b else "none yet"
        self.b_label.value = f"<small>Configuration B (for Compare): {text}</small>"

    def _refresh_table(self) -> None:
        self.table.value = results_table_html(self.results)


def _frame_rate(frames: list[list[float]]) -> float | None:
    """Frames per second while runs were in progress (the gaps between runs left out)."""
    count = sum(len(times) - 1 for times in frames if len(times) > 1)
    span = sum(times[-1] - times[0] for times in frames if len(times) > 1)
    return count / span if span > 0 else None


def _same_settings(a: ExperimentConfig, b: ExperimentConfig) -> bool:
    """True when two configurations differ at most in their labels."""
    return a.with_changes(label="") == b.with_changes(label="")


def _all_widgets(widget):
    yield widget
    for child in getattr(widget, "children", ()):
        yield from _all_widgets(child)
