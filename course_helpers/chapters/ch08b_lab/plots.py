"""Pictures of QoS lab runs, with or without widgets.

``draw_results([result_a, result_b])`` draws finished runs from
:func:`course_helpers.chapters.ch08b_lab.run.run_experiment` as a pyplot figure for a notebook
cell. ``ResultsFigure`` draws the same three panels on a figure it keeps; its
``frame(runs)`` returns a PNG of runs in progress for the lab panel (``panel.py``).
Each run has one colour in all three panels:

1. delivered and lost over time (solid: delivered; dashed: lost by gaps in the
   publication sequence numbers; dotted: DDS ``message_lost`` events; dash-dot:
   ``publish()`` errors);
2. the totals: sent, delivered, the two loss counts, what was still in flight when
   a run was cut short, and the publish errors; "nothing lost" is written for a
   finished run whose every sample arrived, "NOT FINISHED" for a run that ended with
   samples in flight (its delivered count is not its outcome);
3. latency percentiles (p50, p90, p99) on a log scale.

A run is an ``ExperimentResult`` or a ``(label, snapshots)`` pair.

Live frames must be cheap (the kernel is busy receiving samples meanwhile), so
``frame()`` keeps the axes as a rendered background while their limits hold, and
only redraws the lines, bars and numbers on top of it (matplotlib "blitting").
"""

from __future__ import annotations

import io
import math

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

RUN_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b")
TOTALS = (("published", "sent"), ("delivered", "deliv-\nered"), ("lost_by_sequence", "lost\n(gaps)"),
          ("lost_events", "lost\n(events)"), ("in_flight", "in flight\nat end"),
          ("publish_errors", "publish\nerrors"))
PERCENTILES = (("latency_p50_ms", "p50"), ("latency_p90_ms", "p90"), ("latency_p99_ms", "p99"))
_STYLE_KEY = (("-", "delivered", 1.8), ("--", "lost: sequence gaps", 1.3),
              (":", "lost: message_lost events", 1.5), ("-.", "publish errors", 1.0))
_TIMELINE_ATTRS = ("delivered", "lost_by_sequence", "lost_events", "publish_errors")


def _as_run(run) -> tuple[str, list]:
    """(label, snapshots) from an ExperimentResult or a (label, snapshots) pair."""
    if hasattr(run, "timeline"):
        return run.label, list(run.timeline)
    label, snapshots = run
    return str(label), list(snapshots)


def _short(label: str, width: int = 60) -> str:
    return label if len(label) <= width else label[: width - 1] + "…"


def _fmt(value: float) -> str:
    return f"{value:.2g}" if value < 10 else f"{value:.0f}"


def _colour(index: int) -> str:
    return RUN_COLOURS[index % len(RUN_COLOURS)]


def _lost_nothing(snap) -> bool:
    """A finished run whose every sent sample arrived, by both ways of counting."""
    return (snap.done and snap.published > 0 and snap.delivered == snap.published
            and snap.lost_by_sequence == 0 and snap.lost_events == 0 and snap.in_flight == 0)


class ResultsFigure:
    """The lab's three panels on one figure: ``draw()`` for a still picture, ``frame()`` for live PNGs."""

    def __init__(self, figure: Figure | None = None, width_in: float = 12.0, height_in: float = 4.0,
                 dpi: int = 72):
        self.figure = figure if figure is not None else Figure(figsize=(width_in, height_in), dpi=dpi)
        self.figure.clear()
        self.ax_time, self.ax_totals, self.ax_latency = self.figure.subplots(
            1, 3, gridspec_kw={"width_ratios": [1.3, 1.1, 0.8]})
        self.figure.subplots_adjust(left=0.05, right=0.99, bottom=0.17, top=0.80, wspace=0.22)
        self._lines: list[list[Line2D]] = []  # per run: one line per _TIMELINE_ATTRS
        self._dynamic: list = []  # numbers and notes, made again for every picture
        self._bar_cache: dict = {}  # 'totals' / 'latency' -> (run indices, bar containers)
        self._run_legend = None
        self._labels: tuple = ()
        self._limits: tuple | None = None  # (t, samples, totals, latency low, latency high) drawn
        self._background = None
        self._canvas: FigureCanvasAgg | None = None
        self._setup_axes()

    # ------------------------------------------------------------------ public
    def draw(self, runs, title: str | None = None) -> ResultsFigure:
        """Draw ``runs`` (results or (label, snapshots) pairs) with limits fitted to them."""
        runs = [_as_run(run) for run in runs]
        self._update_artists(runs, animated=False)
        self._set_limits(self._needed_limits(runs))
        self._set_run_legend(runs)
        if title:
            self.figure.suptitle(title, fontsize=11, y=0.995)
        return self

    def png(self) -> bytes:
        """The figure as drawn by :meth:`draw`, as PNG bytes."""
        buffer = io.BytesIO()
        self.figure.savefig(buffer, format="png")
        return buffer.getvalue()

    def frame(self, runs, fit: bool = False, expect: tuple[float, int] | None = None) -> bytes:
        """A PNG of ``runs`` in progress, redrawing only what changed.

        While runs are in progress the limits only grow (with room to spare), so the axes
        are re-rendered only now and then; ``expect=(seconds, samples)`` sizes them for the
        whole run from the start. ``fit=True`` fits them to the data (a final frame).
        """
        if self._canvas is None:
            self._canvas = FigureCanvasAgg(self.figure)
        runs = [_as_run(run) for run in runs]
        dynamic = self._update_artists(runs, animated=True)
        needed = self._needed_limits(runs)
        labels = tuple(label for label, _snaps in runs)
        if fit:
            self._set_limits(needed)
            self._background = None  # the next live frame grows from these limits
            self._set_run_legend(runs)
            self._canvas.draw()
        elif self._background is None or labels != self._labels or not _fits(needed, self._limits):
            if expect is not None:
                seconds, samples = expect
                needed = (max(needed[0], seconds), max(needed[1], samples), max(needed[2], samples),
                          *needed[3:])
            self._set_limits(_grown(needed, self._limits if labels == self._labels else None))
            self._set_run_legend(runs)
            self._canvas.draw()  # the axes without the animated artists
            self._background = self._canvas.copy_from_bbox(self.figure.bbox)
        else:
            self._canvas.restore_region(self._background)
        for artist in dynamic:
            if artist.get_visible():
                artist.axes.draw_artist(artist)
        return _encode_png(self._canvas)

    # ------------------------------------------------------------------ building
    def _setup_axes(self) -> None:
        ax = self.ax_time
        ax.set_title("delivered and lost over time", fontsize=10)
        ax.set_xlabel("time since the first sample was sent [s]", fontsize=8)
        ax.set_ylabel("samples (cumulative)", fontsize=8)
        ax.tick_params(labelsize=8)
        ax.legend([Line2D([], [], color="#444444", ls=style, lw=lw) for style, _n, lw in _STYLE_KEY],
                  [name for _s, name, _lw in _STYLE_KEY], fontsize=7, loc="upper left", framealpha=0.8)
        self._hint = ax.text(0.5, 0.5, "press Run: this plot follows the experiment live",
                             ha="center", va="center", transform=ax.transAxes, fontsize=9, color="#666666")
        ax = self.ax_totals
        ax.set_title("totals", fontsize=10)
        ax.tick_params(labelsize=8)
        ax.set_xticks(range(len(TOTALS)))
        ax.set_xticklabels([name for _attr, name in TOTALS], fontsize=7.5)
        ax.set_xlim(-0.6, len(TOTALS) - 0.4)
        ax = self.ax_latency
        ax.set_title("latency (send to callback)", fontsize=10)
        ax.set_ylabel("ms, log scale", fontsize=8)
        ax.tick_params(labelsize=8)
        ax.set_yscale("log")
        ax.yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:g}"))
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.set_xticks(range(len(PERCENTILES)))
        ax.set_xticklabels([name for _attr, name in PERCENTILES], fontsize=8)
        ax.set_xlim(-0.6, len(PERCENTILES) - 0.4)

    def _update_artists(self, runs, animated: bool) -> list:
        """Put the runs' data into lines, bars and texts; return the artists that change."""
        for artist in self._dynamic:
            artist.remove()
        self._dynamic = []
        while len(self._lines) < len(runs):
            colour = _colour(len(self._lines))
            self._lines.append([self.ax_time.plot([], [], color=colour, ls=style, lw=lw)[0]
                                for style, _name, lw in _STYLE_KEY])
        for index, lines in enumerate(self._lines):
            snaps = runs[index][1] if index < len(runs) else []
            t = [s.t for s in snaps]
            for line, attr in zip(lines, _TIMELINE_ATTRS, strict=True):
                line.set_data(t, [getattr(s, attr) for s in snaps])
                line.set_visible(bool(snaps))
        self._hint.set_visible(not any(snaps for _label, snaps in runs))
        totals = [(i, snaps[-1]) for i, (_label, snaps) in enumerate(runs) if snaps]
        latency = [(i, snap) for i, snap in totals if snap.latency_p50_ms is not None]
        total_bars = self._bars(self.ax_totals, "totals", [
            (i, [getattr(snap, attr) for attr, _name in TOTALS]) for i, snap in totals])
        latency_bars = self._bars(self.ax_latency, "latency", [
            (i, [max(getattr(snap, attr), 1e-3) for attr, _name in PERCENTILES]) for i, snap in latency])
        # Numbers on the bars of finished runs only: text is what costs most in a live frame.
        for (_i, snap), bars in zip(totals, total_bars, strict=True):
            if snap.done:
                self._dynamic += self.ax_totals.bar_label(  # heights, not the values bars were made with
                    bars, labels=[f"{round(b.get_height())}" for b in bars], fontsize=6.5, padding=1)
        for (_i, snap), bars in zip(latency, latency_bars, strict=True):
            if snap.done:
                self._dynamic += self.ax_latency.bar_label(
                    bars, labels=[_fmt(b.get_height()) for b in bars], fontsize=6.5, padding=1)
        notes = [(i, "nothing lost") for i, snap in totals if _lost_nothing(snap)]
        notes += [(i, f"NOT FINISHED: {snap.in_flight} in flight, not lost") for i, snap in totals
                  if snap.done and snap.in_flight]  # its delivered bar is no result to compare
        for line, (index, note) in enumerate(notes):
            self._dynamic.append(self.ax_totals.text(
                0.98, 0.95 - 0.09 * line, note, ha="right", va="top", fontsize=8.5,
                fontweight="bold", color=_colour(index), transform=self.ax_totals.transAxes))
        if totals and not latency:
            self._dynamic.append(self.ax_latency.text(
                0.5, 0.5, "no samples delivered", ha="center", va="center",
                transform=self.ax_latency.transAxes, fontsize=9, color="#666666"))
        changing = ([line for lines in self._lines for line in lines] + self._dynamic
                    + [bar for bars in total_bars + latency_bars for bar in bars])
        for artist in changing:
            artist.set_animated(animated)
        return changing

    def _bars(self, ax, kind: str, entries: list) -> list:
        """Grouped bars, one group per x tick and one colour per run; reused while the runs stay."""
        key = tuple(index for index, _values in entries)
        cached_key, cached = self._bar_cache.get(kind, ((), []))
        if key != cached_key:
            for bars in cached:
                bars.remove()
            width = 0.8 / max(len(entries), 1)
            cached = []
            for slot, (index, values) in enumerate(entries):
                xs = [k + (slot - (len(entries) - 1) / 2) * width for k in range(len(values))]
                cached.append(ax.bar(xs, values, width=width, color=_colour(index)))
            self._bar_cache[kind] = (key, cached)
        else:
            for bars, (_index, values) in zip(cached, entries, strict=True):
                for bar, value in zip(bars, values, strict=True):
                    bar.set_height(value)
        return cached

    def _set_run_legend(self, runs) -> None:
        if self._run_legend is not None:
            self._run_legend.remove()
            self._run_legend = None
        self._labels = tuple(label for label, _snaps in runs)
        if runs:
            handles = [Line2D([], [], color=_colour(i), lw=6) for i in range(len(runs))]
            self._run_legend = self.figure.legend(
                handles, [_short(label) for label, _s in runs], loc="upper center",
                bbox_to_anchor=(0.5, 0.93), ncol=min(len(runs), 3), fontsize=8, frameon=False)

    # ------------------------------------------------------------------ limits
    @staticmethod
    def _needed_limits(runs) -> tuple:
        """(t max, samples max, totals max, latency min, latency max) the runs need."""
        t_max = samples = totals = 0.0
        lat_low, lat_high = math.inf, 0.0
        for _label, snaps in runs:
            if not snaps:
                continue
            last = snaps[-1]
            t_max = max(t_max, last.t)
            samples = max(samples, *(getattr(last, attr) for attr in _TIMELINE_ATTRS))  # cumulative
            totals = max(totals, *(getattr(last, attr) for attr, _name in TOTALS))
            for attr, _name in PERCENTILES:
                value = getattr(last, attr)
                if value is not None:
                    lat_low, lat_high = min(lat_low, max(value, 1e-3)), max(lat_high, value)
        if lat_high == 0.0:
            lat_low, lat_high = 1.0, 10.0
        return (max(t_max, 0.5), max(samples, 10.0), max(totals, 1.0), lat_low, lat_high)

    def _set_limits(self, limits: tuple) -> None:
        t_max, samples, totals, lat_low, lat_high = limits
        self.ax_time.set_xlim(0, t_max * 1.03)
        self.ax_time.set_ylim(0, samples * 1.35)  # headroom for the style legend
        self.ax_totals.set_ylim(0, totals * 1.3)
        self.ax_latency.set_ylim(lat_low / 3, lat_high * 8)
        self._limits = limits


def _fits(needed: tuple, drawn: tuple | None) -> bool:
    if drawn is None:
        return False
    return (needed[0] <= drawn[0] and needed[1] <= drawn[1] and needed[2] <= drawn[2]
            and needed[3] >= drawn[3] and needed[4] <= drawn[4])


def _grown(needed: tuple, drawn: tuple | None) -> tuple:
    """Limits with room to grow, so a live plot re-renders its axes only now and then."""
    t_max, samples, totals, lat_low, lat_high = needed
    grown = (t_max * 1.5, samples * 1.5, totals * 1.5, lat_low / 10, lat_high * 10)
    if drawn is None:
        return grown
    return (max(grown[0], drawn[0]), max(grown[1], drawn[1]), max(grown[2], drawn[2]),
            min(grown[3], drawn[3]), max(grown[4], drawn[4]))


def _encode_png(canvas: FigureCanvasAgg) -> bytes:
    from PIL import Image

    width, height = canvas.get_width_height()
    image = Image.frombuffer("RGBA", (width, height), canvas.buffer_rgba(), "raw", "RGBA", 0, 1)
    buffer = io.BytesIO()
    image.save(buffer, format="png", compress_level=1)
    return buffer.getvalue()


def draw_results(runs, title: str | None = None, width_in: float = 12.0, height_in: float = 4.0):
    """Draw finished runs as a pyplot figure and return it.

    Args:
        runs: ``ExperimentResult`` objects or ``(label, snapshots)`` pairs (one run alone is fine).
        title: the figure's title.
        width_in, height_in: the figure's size in inches.

    Returns:
        The matplotlib Figure. End the cell with ``plt.show()`` so only the picture is shown.
    """
    import matplotlib.pyplot as plt

    if not isinstance(runs, (list, tuple)):
        runs = [runs]
    figure = plt.figure(figsize=(width_in, height_in), dpi=100)
    ResultsFigure(figure).draw(runs, title)
    return figure


def draw_still(runs, title: str | None = None, width_in: float = 12.0, height_in: float = 4.0):
    """Like :func:`draw_results`, but a Figure of its own outside pyplot (safe in any thread, never
    shown by the notebook's inline backend): for pictures saved as files or records."""
    if not isinstance(runs, (list, tuple)):
        runs = [runs]
    still = ResultsFigure(width_in=width_in, height_in=height_in, dpi=100)
    FigureCanvasAgg(still.figure)
    return still.draw(runs, title).figure
