"""The live graph widget: the picture redrawn in the background while the notebook keeps running."""

from __future__ import annotations

import functools
import threading

from course_helpers.core.errors import CourseError
from course_helpers.viz.render import render_png
from course_helpers.viz.snapshot import GraphSnapshot, resolve_runtime, snapshot_of

REFRESHER_THREAD_NAME = "ros-graph-refresher"
_live_lock = threading.Lock()
_live_views: list = []  # the refreshing view of this kernel (at most one keeps running)


def _graph_key(snap: GraphSnapshot, show_services: bool):
    return (snap.domain_id, tuple(snap.nodes), tuple(snap.topics.items()), tuple(snap.edges),
            tuple(snap.action_edges), tuple(snap.actions),
            tuple(snap.service_edges) if show_services else (), show_services)


class _LiveGraphController:
    """The refresher thread behind :func:`live_graph` (redraws only when the graph changed)."""

    def __init__(self, rt, view, period_s: float):
        self.rt = rt
        self.view = view
        self.period_s = period_s
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._last_key = None
        self.snapshot: GraphSnapshot | None = None  # the graph last drawn
        self.redraws = 0
        self.refreshes = 0  # looks at the graph so far, drawn or not (a test waits for a few)
        self.thread = threading.Thread(target=self._loop, name=REFRESHER_THREAD_NAME, daemon=True)

    def start(self):
        self.thread.start()

    def stop(self, reason: str = "stopped") -> None:
        self._stop.set()
        self._wake.set()
        if self.thread.is_alive() and threading.current_thread() is not self.thread:
            self.thread.join(timeout=5)
        self.view.status.value = f"<small><i>{reason}</i></small>"

    @property
    def running(self) -> bool:
        return self.thread.is_alive() and not self._stop.is_set()

    def kick(self) -> None:
        """Redraw at once (the checkbox and the button call this)."""
        self._last_key = None
        self._wake.set()

    def _loop(self) -> None:
        while not self._stop.is_set():
            if self.view.auto.value or self._last_key is None:
                self.refresh()
            self._wake.wait(self.period_s)
            self._wake.clear()

    def refresh(self) -> None:
        self.refreshes += 1
        # Never go through rt.graph here: it would start a runtime that the notebook stopped.
        graph, domain = self.rt.graph_if_running(), getattr(self.rt, "domain", None)
        if graph is None or domain is None:
            self.view.status.value = "<small><i>runtime stopped: run rt = get_runtime()</i></small>"
            return
        try:
            snap = snapshot_of(graph, domain.domain_id, include_hidden=self.view.hidden.value)
            show_services = self.view.services.value
            key = (_graph_key(snap, show_services), snap.include_hidden)
            if key != self._last_key:
                self.view.image.value = render_png(snap, show_services=show_services)
                self._last_key = key
                self.snapshot = snap
                self.redraws += 1
            self.view.status.value = (f"<small>{_count(len(snap.nodes), 'node')}, "
                                      f"{_count(len(snap.topics), 'topic')}</small>")
        except Exception as exc:  # keep refreshing; show what went wrong
            self.view.status.value = f"<small>graph refresh failed: {type(exc).__name__}: {exc}</small>"


def _count(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


@functools.cache
def _view_class():
    """The widget class of :func:`live_graph` (built on first use, so importing ipywidgets is lazy)."""
    import ipywidgets as w

    class LiveGraphView(w.VBox):
        """The live graph widget; ``stop()`` ends its refresher, ``close()`` also removes it."""

        def stop(self, reason: str = "stopped") -> None:
            self.controller.stop(reason)
            with _live_lock:
                if self in _live_views:
                    _live_views.remove(self)

        def close(self):
            self.stop("closed")
            for child in (self.image, self.hidden, self.services, self.auto, self.refresh_button,
                          self.status, self.controls):
                child.close()
            super().close()

        def __repr__(self):  # stable text: notebooks compare text outputs
            return f"LiveGraphView(period_s={self.period_s:g})"

    return LiveGraphView


def live_graph(rt=None, period_s: float = 1.0, include_hidden: bool = False, show_services: bool = False):
    """A widget showing the live ROS graph, redrawn every ``period_s`` seconds in the background.

    The kernel stays free: a background thread asks the graph and redraws only when
    it changed. Checkboxes toggle hidden infrastructure and services; "auto refresh"
    pauses the updates. Calling ``live_graph`` again (e.g. re-running the cell)
    stops the previous view's thread; ``view.close()`` or ``view.stop()`` stops it too.
    """
    import ipywidgets as w

    from course_helpers.notebook.widget_errors import owned

    if isinstance(period_s, bool) or not isinstance(period_s, (int, float)) or not 0.2 <= period_s <= 60:
        raise CourseError(f"period_s must be a number of seconds between 0.2 and 60, got {period_s!r}")
    rt = resolve_runtime(rt)
    stop_live_graphs("replaced by a newer live graph")

    image = w.Image(format="png", layout=w.Layout(max_width="100%"))
    hidden = w.Checkbox(value=include_hidden, description="show hidden", indent=False,
                        layout=w.Layout(width="auto"))
    services = w.Checkbox(value=show_services, description="show services", indent=False,
                          layout=w.Layout(width="auto"))
    auto = w.ToggleButton(value=True, description="auto refresh", icon="refresh",
                          tooltip=f"redraw every {period_s:g} s when the graph changes")
    refresh_button = w.Button(description="refresh now", layout=w.Layout(width="auto"))
    status = w.HTML()
    for control in (hidden, services, auto, refresh_button):
        control.layout.margin = "0 12px 0 0"
    controls = w.HBox([hidden, services, auto, refresh_button, status],
                      layout=w.Layout(align_items="center"))
    view = _view_class()([controls, image])
    view.period_s = float(period_s)
    view.image, view.hidden, view.services, view.auto = image, hidden, services, auto
    view.refresh_button, view.status, view.controls = refresh_button, status, controls
    view.controller = _LiveGraphController(rt, view, float(period_s))
    hidden.observe(lambda _change: view.controller.kick(), names="value")
    services.observe(lambda _change: view.controller.kick(), names="value")
    auto.observe(lambda _change: view.controller.kick(), names="value")
    refresh_button.on_click(lambda _button: view.controller.kick())
    owned(view, "live graph", inside=True)  # an error of its callbacks: one line at its end
    with _live_lock:
        _live_views.append(view)
    view.controller.start()
    return view


def stop_live_graphs(reason: str = "stopped") -> None:
    """Stop every live graph refresher of this kernel."""
    with _live_lock:
        views = list(_live_views)
    for view in views:
        view.stop(reason)


def refresher_threads() -> list[threading.Thread]:
    """The live graph refresher threads still running (tests check there is at most one)."""
    return [t for t in threading.enumerate() if t.name == REFRESHER_THREAD_NAME and t.is_alive()]
