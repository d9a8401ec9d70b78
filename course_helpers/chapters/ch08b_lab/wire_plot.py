"""Timelines of captured lossy-link runs (notebook 08c): a repair, and a gap nobody repairs.

``draw_repair_timeline(reliable, best_effort)`` draws, as a sequence diagram, the writer's lane
above the reader's, with one vertical arrow per submessage at the moment the capture saw it
(on the loopback a datagram takes microseconds, so an arrow's length is no time):

* top, a reliable run's :class:`~.wire.Repair`: the lost copy (red, crossed where the link dropped
  it), the writer's HEARTBEATs (blue, down), the reader's ACKNACK naming the sample (orange, up),
  and the copy that arrived (green); the other samples in the window are grey;
* bottom, a best-effort run around one lost sample: the writer moves on, nothing comes back.
"""

from __future__ import annotations

from course_helpers.chapters.ch08b_lab.wire import Repair, WireRun
from course_helpers.core.errors import CourseError

WRITER_Y, READER_Y = 1.0, 0.0
COLOURS = {"lost": "#d62728", "HEARTBEAT": "#1f77b4", "ACKNACK": "#ff7f0e", "arrived": "#2ca02c",
           "other": "#b0b0b0"}
MARGIN_S = 0.012  # s of context before the first lost copy and after the repair
BEST_EFFORT_WINDOW_S = 0.03  # s shown on each side of a best-effort loss


def pick_repair(run: WireRun, seq: int | None = None) -> Repair:
    """The repair of sample ``seq``, or (None) the run's quickest repair, whose few milliseconds fit one
    picture (one whose HEARTBEAT came after the loss, if there is such a repair: the usual story);
    CourseError if there is none."""
    repairs = run.repairs
    chosen = [r for r in repairs if seq in (None, r.seq)]
    if not chosen:
        what = f"sample {seq}" if seq is not None else "any sample"
        raise CourseError(f"the run has no repair of {what} (repaired: {[r.seq for r in repairs][:20]})")
    usual = [r for r in chosen if r.heartbeat is not None and r.heartbeat.frame > r.lost[0].frame]
    return min(usual or chosen, key=lambda r: (r.waited_s, r.seq))


def _arrow(ax, t_ms: float, upward: bool, colour: str, dropped: bool, width: float) -> None:
    start, end = (READER_Y, WRITER_Y) if upward else (WRITER_Y, READER_Y)
    if dropped:  # the link dropped it on the way: half an arrow and a cross
        middle = (start + end) / 2
        ax.plot([t_ms, t_ms], [start, middle], color=colour, lw=width)
        ax.plot([t_ms], [middle], marker="x", color=colour, markersize=9, mew=2)
        return
    ax.annotate("", xy=(t_ms, end), xytext=(t_ms, start),
                arrowprops={"arrowstyle": "-|>", "color": colour, "lw": width, "shrinkA": 0, "shrinkB": 0})


def _lanes(ax, title: str, start_ms: float, end_ms: float) -> None:
    ax.set_yticks([READER_Y, WRITER_Y], ["reader\n(subscriber)", "writer\n(publisher)"])
    ax.set_ylim(-1.8, 2.4)
    ax.set_xlim(start_ms, end_ms)  # arrows (annotations) do not widen the axes by themselves
    ax.axhline(WRITER_Y, color="black", lw=0.6)
    ax.axhline(READER_Y, color="black", lw=0.6)
    ax.set_title(title, fontsize=10, loc="left")
    ax.set_xlabel("ms since the lost copy was sent (the capture's clock)")


def _label(ax, t_ms: float, above: bool, text: str, colour: str) -> None:
    ax.text(t_ms, WRITER_Y + 0.08 if above else READER_Y - 0.08, text, rotation=90, fontsize=7.5,
            color=colour, ha="right", va="bottom" if above else "top")


def draw_repair(ax, run: WireRun, repair: Repair) -> None:
    """The reliable panel: ``repair`` and the submessages around it."""
    t0 = repair.lost[0].time
    start, end = t0 - MARGIN_S, repair.resent.time + MARGIN_S
    named = {id(s) for s in (*repair.lost, repair.heartbeat, repair.acknack, repair.resent) if s}
    for s in run.submessages:
        if not start <= s.time <= end or id(s) in named:
            continue
        if s.kind == "HEARTBEAT":
            _arrow(ax, (s.time - t0) * 1e3, False, COLOURS["HEARTBEAT"], s.dropped, 1.0)
        elif s.kind == "ACKNACK":
            _arrow(ax, (s.time - t0) * 1e3, True, COLOURS["ACKNACK"], s.dropped, 1.0)
        elif s.kind == "DATA":
            _arrow(ax, (s.time - t0) * 1e3, False, COLOURS["other"], s.dropped, 0.6)
    for copy in repair.lost:
        _arrow(ax, (copy.time - t0) * 1e3, False, COLOURS["lost"], True, 2.0)
        _label(ax, (copy.time - t0) * 1e3, True, f"DATA {repair.seq} lost", COLOURS["lost"])
    if repair.heartbeat is not None:
        hb = repair.heartbeat
        _arrow(ax, (hb.time - t0) * 1e3, False, COLOURS["HEARTBEAT"], False, 2.0)
        _label(ax, (hb.time - t0) * 1e3, True, f"HEARTBEAT {hb.first}..{hb.last}", COLOURS["HEARTBEAT"])
    if repair.acknack is not None:
        ack = repair.acknack
        _arrow(ax, (ack.time - t0) * 1e3, True, COLOURS["ACKNACK"], False, 2.0)
        others = f" +{len(ack.numbers) - 1}" if len(ack.numbers) > 1 else ""  # the other numbers it asks for
        _label(ax, (ack.time - t0) * 1e3, False, f"ACKNACK for {repair.seq}{others}", COLOURS["ACKNACK"])
    _arrow(ax, (repair.resent.time - t0) * 1e3, False, COLOURS["arrived"], False, 2.0)
    _label(ax, (repair.resent.time - t0) * 1e3, True, f"DATA {repair.seq} again", COLOURS["arrived"])
    _lanes(ax, f"{run.config.describe()}: sample {repair.seq} repaired after "
               f"{repair.waited_s * 1e3:.0f} ms (grey: other samples)", (start - t0) * 1e3, (end - t0) * 1e3)


def draw_gap(ax, run: WireRun, seq: int | None = None) -> None:
    """The best-effort panel: one lost sample (``seq``, or the first lost) and what follows: nothing."""
    lost = run.lost if seq is None else [seq]
    if not lost:
        raise CourseError("the run lost no sample, so there is no gap to draw")
    copies = [s for s in run.data(lost[0]) if s.dropped]
    if not copies:
        raise CourseError(f"the link dropped no copy of sample {lost[0]}")
    t0 = copies[0].time
    for s in run.submessages:
        if abs(s.time - t0) <= BEST_EFFORT_WINDOW_S:
            colour = COLOURS["lost"] if s.seq == lost[0] else COLOURS["other"]
            _arrow(ax, (s.time - t0) * 1e3, s.kind in ("ACKNACK", "NACK_FRAG"), colour, s.dropped,
                   2.0 if s.seq == lost[0] else 0.6)
    _label(ax, 0.0, True, f"DATA {lost[0]} lost", COLOURS["lost"])
    heartbeats, acknacks = run.counts()["HEARTBEAT"][0], run.counts()["ACKNACK"][0]
    window_ms = BEST_EFFORT_WINDOW_S * 1e3
    _lanes(ax, f"{run.config.describe()}: sample {lost[0]} never sent again "
               f"({heartbeats} HEARTBEATs and {acknacks} ACKNACKs in the whole run)", -window_ms, window_ms)


def draw_repair_timeline(reliable: WireRun, best_effort: WireRun | None = None, seq: int | None = None,
                         width_in: float = 12.0):
    """A pyplot figure: the repair of sample ``seq`` (or the run's first) in ``reliable``, and, if given,
    a gap of ``best_effort``. End the cell with ``plt.show()``."""
    import matplotlib.pyplot as plt

    for run in (reliable, best_effort):
        if run is not None and not isinstance(run, WireRun):
            raise CourseError("draw_repair_timeline() takes WireRun objects (from capture_run), "
                              f"got {type(run).__name__}")
    rows = 2 if best_effort is not None else 1
    figure, axes = plt.subplots(rows, 1, figsize=(width_in, 3.6 * rows), dpi=100, squeeze=False)
    draw_repair(axes[0][0], reliable, pick_repair(reliable, seq))
    if best_effort is not None:
        draw_gap(axes[1][0], best_effort)
    figure.tight_layout()
    return figure
