"""Retune a running node's publish rate through its parameter services, and measure what it really does.

:class:`RateTuner` talks to the node's parameter services as ``ros2 param set`` does,
counts the messages that arrive on its topic (their rate from the times the talker published them,
so a burst of late deliveries on a busy machine does not read as a faster talker), plots
requested against measured rate, and offers a slider widget that retunes live. The widget's
plot is drawn in a thread of its own, never in the executor thread: drawing there would delay
the very timers it measures.
:meth:`RateTuner.show` displays the widget with a static record of its final state (the rate
set, the rate measured for it, and the plot), which is what a saved copy of the notebook shows.
"""

from __future__ import annotations

import html
import io
import math
import threading
import time
from collections import deque

from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient

from course_helpers.core.errors import CourseError
from course_helpers.core.names import as_full_name
from course_helpers.core.runtime import get_runtime
from course_helpers.core.validation import check_topic_name, resolve_interface

RECORD_AFTER_SLIDER_S = 2.5  # after a slider move, the record waits this long so the 1 s window is new
RECORD_TITLE = "rate tuner"
NODE_GONE_NOTE = "<i>the rate_tuner node was removed: run the cell again to tune</i>"


class _TunerNode(Node):
    """The tuner's own node. Destroying it (``rt.remove``, a re-run, a runtime stop) sets ``gone``
    and wakes the drawing thread, which then ends: an event, however busy the machine is."""

    def __init__(self, name: str, gone: threading.Event, wake: threading.Event):
        super().__init__(name)
        self.gone, self.wake = gone, wake

    def destroy_node(self):
        try:
            return super().destroy_node()
        finally:
            self.gone.set()
            self.wake.set()


class RateTuner:
    """Retune a running node's publish rate through its parameter services and measure the result.

    ``RateTuner('/talker', 'chatter')`` adds a helper node ``rate_tuner`` (re-running
    replaces it) that subscribes to the topic and talks to ``/talker``'s parameter
    services like ``ros2 param set`` does. :meth:`set_rate` changes ``rate_hz``,
    :meth:`measure` counts what really arrives, :meth:`plot` draws requested vs
    measured rate over time, and :meth:`widget` is a slider that does it live.

    Args:
        target: the node to retune ('/talker' or 'talker').
        topic: the topic it publishes on, of type ``msg_type``.
        parameter: the rate parameter [Hz], a double.
        minimum, maximum: the slider's range [Hz].
        rt: the runtime (default: this kernel's).

    Raises :class:`CourseError` if the target has no parameter services or no such parameter.
    """

    def __init__(self, target: str, topic: str, msg_type="std_msgs/msg/String", parameter: str = "rate_hz",
                 minimum: float = 0.5, maximum: float = 20.0, rt=None):
        self.rt = rt or get_runtime()
        self.target = as_full_name(target)
        check_topic_name(topic)
        self.topic = topic
        self.parameter = parameter
        self.minimum, self.maximum = float(minimum), float(maximum)
        self.started = time.monotonic()
        # (monotonic arrival time [s], the publisher's source timestamp [s]) of each message
        self.arrivals: deque[tuple[float, float]] = deque(maxlen=5000)
        self.setpoints: list[tuple[float, float]] = []  # (seconds since start, requested Hz)
        self.samples: list[tuple[float, float]] = []  # rolling rate: (seconds since start, Hz)
        self.measurements: list[tuple[float, float]] = []  # measure() results: (seconds since start, Hz)
        self._widgets = None
        self._ticks = 0
        self._redraw = threading.Event()  # set by the timer (executor thread), served by the drawing thread
        self.gone = threading.Event()  # set when the tuner's node is destroyed
        self._note = ("", 0.0)  # (HTML message, shown until this time)
        self._lock = threading.Lock()
        self.record = None  # the static record shown by show()
        self.last_measurement: tuple[float, float, float] | None = None  # (requested, measured Hz, seconds)
        self.last_refusal: tuple[float, str] | None = None  # (requested Hz, reason)
        self._syncing = False  # set while set_rate moves the slider (no second set_parameters call)
        self._record_due: float | None = None  # monotonic time at which a slider move gets recorded
        self.node = self.rt.add(_TunerNode, "rate_tuner", self.gone, self._redraw, console=False)
        self.client = AsyncParameterClient(self.node, self.target)
        self.node.create_subscription(resolve_interface(msg_type, "msg"), topic, self._on_message, 10)
        self.node.create_timer(0.5, self._tick)  # rolling measurement and live refresh [s]
        if not self.client.wait_for_services(5.0):
            raise CourseError(f"node {self.target} has no parameter services; is it running? "
                              f"`%ros2 node list` shows the nodes there are")
        current = self.get_rate()
        self.setpoints.append((0.0, current))

    # ------------------------------------------------------------------ parameter access
    def get_rate(self) -> float:
        """The target's current ``rate_hz``, read through its get_parameters service."""
        response = self.rt.wait_for_future(self.client.get_parameters([self.parameter]), 3.0,
                                           f"{self.target}'s {self.parameter}")
        if not response.values or response.values[0].type == 0:
            raise CourseError(f"{self.target} has no parameter {self.parameter!r}")
        return parameter_value_to_python(response.values[0])

    def set_rate(self, hz: float):
        """Ask the target to use ``hz``; returns the SetParametersResult (``successful``, ``reason``)."""
        if isinstance(hz, bool) or not isinstance(hz, (int, float)) or not math.isfinite(hz):
            raise CourseError(f"rate must be a number of Hz, got {hz!r}")
        request = [Parameter(self.parameter, value=float(hz))]
        response = self.rt.wait_for_future(self.client.set_parameters(request), 3.0,
                                           f"{self.target} to set {self.parameter}")
        result = response.results[0]
        if result.successful:
            with self._lock:
                self.setpoints.append((self._now(), float(hz)))
            self._move_slider(float(hz))
        else:
            self.last_refusal = (float(hz), result.reason)
        return result

    @property
    def requested(self) -> float:
        """The rate [Hz] last set (or read at start)."""
        with self._lock:
            return self.setpoints[-1][1]

    def _move_slider(self, hz: float) -> None:
        """Show a rate set from code on the slider too (the slider then does not set it again)."""
        if self._widgets is None:
            return
        slider = self._widgets[0]
        if slider.value != hz:
            self._syncing = True
            try:
                slider.value = hz
            finally:
                self._syncing = False

    # ------------------------------------------------------------------ measuring
    def measure(self, seconds: float = 1.5, settle_s: float = 0.3) -> float:
        """Wait ``settle_s``, then return the rate [Hz] of messages that arrive during ``seconds``."""
        time.sleep(settle_s)
        start = time.monotonic()
        time.sleep(seconds)
        end = time.monotonic()
        rate = self._rate_between(start, end)
        with self._lock:
            self.measurements.append(((start + end) / 2 - self.started, rate))
        self.last_measurement = (self.requested, rate, seconds)
        self.update_record()
        return rate

    def rolling_rate(self, window_s: float = 1.0) -> float:
        """The rate [Hz] of the messages of the last ``window_s`` seconds."""
        now = time.monotonic()
        return self._rate_between(now - window_s, now)

    def _rate_between(self, start: float, end: float) -> float:
        """Messages per second among those that arrived between two monotonic times.

        The rate is the talker's: from the spacing of the messages' source timestamps (when
        ``publish()`` ran), not of their arrivals, which a busy subscriber takes in bursts."""
        with self._lock:
            published = [stamp for arrived, stamp in self.arrivals if start <= arrived <= end]
        if len(published) >= 3 and max(published) > min(published):
            return (len(published) - 1) / (max(published) - min(published))
        return len(published) / (end - start)

    def _on_message(self, _msg, info) -> None:
        """Note when a message arrived and when it was published (``info``: rmw's message info)."""
        with self._lock:
            self.arrivals.append((time.monotonic(), info["source_timestamp"] / 1e9))

    def _now(self) -> float:
        return time.monotonic() - self.started

    def _tick(self) -> None:
        self._ticks += 1
        if self._now() >= 1.0:
            rate = self.rolling_rate()
            with self._lock:
                self.samples.append((self._now() - 0.5, rate))
                del self.samples[:-600]
        if self._widgets is not None and self._ticks % 2 == 0:  # redraw once a second
            self._redraw.set()

    # ------------------------------------------------------------------ pictures and widgets
    def draw(self, ax) -> None:
        """Draw requested (steps) and measured (dots) rate over time on a matplotlib Axes."""
        with self._lock:
            setpoints = list(self.setpoints)
            samples = sorted(self.samples)
            measurements = list(self.measurements)
        end = max([self._now()] + [t for t, _ in samples])
        xs = [t for t, _ in setpoints] + [end]
        ys = [hz for _, hz in setpoints] + [setpoints[-1][1]]
        ax.step(xs, ys, where="post", color="#2563eb", linewidth=2, label=f"requested {self.parameter}")
        if samples:
            ax.plot([t for t, _ in samples], [hz for _, hz in samples], "-", color="#f97316",
                    linewidth=1, alpha=0.8, label=f"measured on {self.topic} (1 s window)")
        if measurements:
            ax.plot([t for t, _ in measurements], [hz for _, hz in measurements], "D", color="#c2410c",
                    markersize=7, label="measure() result")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("rate [Hz]")
        top = max(ys + [hz for _, hz in samples + measurements] + [1.0])
        ax.set_ylim(0, top * 1.25)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", fontsize=8)
        ax.set_title(f"{self.target}: requested vs measured publish rate", fontsize=10)

    def plot(self):
        """A matplotlib Figure of requested vs measured rate (pyplot, for a notebook cell)."""
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7.5, 3.2))
        self.draw(ax)
        fig.tight_layout()
        return fig

    def widget(self):
        """A slider that sets the rate live, a measured-rate label and a plot refreshed twice a second."""
        import ipywidgets as widgets

        current = self.setpoints[-1][1]
        slider = widgets.FloatSlider(value=current, min=self.minimum, max=self.maximum, step=0.5,
                                     description=f"{self.parameter}", continuous_update=False)
        label = widgets.HTML()
        image = widgets.Image(format="png")
        slider.observe(lambda change: None if self._syncing else self._on_slider(change["new"], label),
                       names="value")
        first = self._widgets is None
        self._widgets = (slider, label, image)
        self._refresh_widgets()
        if first:
            threading.Thread(target=self._draw_when_asked, name="rate-tuner-plot", daemon=True).start()
        return widgets.VBox([widgets.HBox([slider, label]), image])

    def show(self) -> None:
        """Display :meth:`widget` with a static record of the tuner's state (updated by :meth:`measure`
        and after slider moves), so that a saved copy of the notebook shows the final state."""
        from course_helpers.notebook.records import show_with_record

        widget = self.widget()
        text, body = self._record_body()
        self.record = show_with_record(widget, RECORD_TITLE, text, body)

    def update_record(self) -> None:
        """Replace the static record with the current state and plot (nothing before :meth:`show`)."""
        if self.record is None:
            return
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=(7.5, 3.0), dpi=80)
        FigureCanvasAgg(fig)
        self.draw(fig.add_subplot())
        fig.tight_layout()
        text, body = self._record_body()
        self.record.update(text, html_body=body, figure=fig)

    def _record_body(self) -> tuple[str, str]:
        """The record as text and HTML: the rate set, and the rate measured for that setting."""
        requested = self.requested
        lines = [f"{self.target}: {self.parameter} set to {requested:.1f} Hz"]
        measured = self.last_measurement
        if measured is not None and measured[0] == requested:
            lines.append(f"measured on {self.topic}: {measured[1]:.1f} Hz (measure() over {measured[2]:g} s "
                         "at this setting)")
        elif self._now() - self.setpoints[-1][0] >= 1.5:  # the 1 s window holds only this setting
            lines.append(f"measured on {self.topic}: {self.rolling_rate():.1f} Hz (the last 1 s)")
        else:
            lines.append(f"not measured yet at {requested:.1f} Hz")
        if self.last_refusal is not None:
            hz, reason = self.last_refusal
            lines.append(f"last refused: {hz:g} Hz ({reason})")
        text = "\n".join(lines)
        body = "<p><b>Rate tuner</b> (final state)</p><pre>" + html.escape(text) + "</pre>"
        return text, body

    def _on_slider(self, hz: float, label) -> None:
        if self.gone.is_set():
            label.value = NODE_GONE_NOTE
            return
        try:
            result = self.set_rate(hz)
            problem = "" if result.successful else f"rejected: {result.reason}"
        except (CourseError, TimeoutError) as error:
            problem = str(error)
        if problem:
            self._note = (f"<span style='color:#cf222e'>{problem}</span>", time.monotonic() + 4.0)
            label.value = self._note[0]
        self._record_due = time.monotonic() + RECORD_AFTER_SLIDER_S

    def _draw_when_asked(self) -> None:
        """The drawing thread: redraw whenever the timer asks; end when the tuner's node is destroyed,
        saying so in the widget.

        A slider move is recorded here too, once the 1 s measuring window holds only the new rate."""
        while True:
            self._redraw.wait()
            self._redraw.clear()
            if self.gone.is_set():
                break
            self._refresh_widgets()
            if self._record_due is not None and time.monotonic() >= self._record_due:
                self._record_due = None
                self.update_record()
        slider, label, _image = self._widgets
        slider.disabled = True
        label.value = NODE_GONE_NOTE

    def _refresh_widgets(self) -> None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        _slider, label, image = self._widgets
        note, until = self._note
        label.value = note if time.monotonic() < until else f"measured: <b>{self.rolling_rate():.1f} Hz</b>"
        fig = Figure(figsize=(7.5, 3.0), dpi=80)
        FigureCanvasAgg(fig)
        self.draw(fig.add_subplot())
        fig.tight_layout()
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png")
        image.value = buffer.getvalue()
