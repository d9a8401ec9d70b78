"""A progress bar with a label that leaves a static record: live in JupyterLab, readable when saved.

:class:`ProgressWithRecord` is the one progress widget of the course. Chapter 05 drives it with an
action's feedback (``FeedbackProgress``), chapter 09 with the lines a build prints
(``build_progress``). The record (:mod:`.records`) is what a saved copy of the notebook shows:
the caller fills it in when the run ends.
"""

from __future__ import annotations

from course_helpers.notebook.records import Record, show_with_record

END_STYLES = {"success", "warning", "danger", "info", ""}  # ipywidgets' bar styles


class ProgressWithRecord:
    """A bar from 0 to ``maximum`` and a label beside it; :meth:`show` displays it with its record.

    Args:
        title: names the record (and the bar, if ``describe`` is true).
        maximum: the value of a full bar.
        label: the label's first text.
        describe: write ``title`` in front of the bar.
        width: the bar's CSS width (default: ipywidgets').
        style: the bar's first style (``'info'`` for a bar that only creeps, '' for none).
    """

    def __init__(self, title: str, maximum: float = 1.0, label: str = "", describe: bool = False,
                 width: str | None = None, style: str = ""):
        import ipywidgets as widgets

        self.title = title
        self.maximum = float(maximum)
        layout = widgets.Layout(width=width) if width else widgets.Layout()
        self.bar = widgets.FloatProgress(value=0.0, min=0.0, max=self.maximum, bar_style=style,
                                         description=title if describe else "", layout=layout,
                                         style={"description_width": "initial"})
        self.label = widgets.Label(value=label)
        self.widget = widgets.HBox([self.bar, self.label])
        self.record: Record | None = None

    def move(self, value: float, label: str | None = None) -> None:
        """Set the bar to ``value`` (held within 0 and the maximum) and, if given, the label."""
        self.bar.value = min(max(float(value), 0.0), self.maximum)
        if label is not None:
            self.label.value = label

    def end(self, style: str, label: str | None = None, full: bool = False) -> None:
        """Colour the bar for how the run ended ('success', 'warning', 'danger'); ``full`` fills it."""
        if style not in END_STYLES:
            raise ValueError(f"style must be one of {sorted(END_STYLES)}, got {style!r}")
        self.bar.bar_style = style
        if full:
            self.bar.value = self.maximum
        if label is not None:
            self.label.value = label

    def show(self, text: str, html_body: str | None = None) -> Record:
        """Display the bar with a record holding ``text`` (and ``html_body`` for HTML readers)."""
        self.record = show_with_record(self.widget, self.title, text, html_body)
        return self.record

    def update_record(self, text: str, html_body: str | None = None) -> None:
        """Replace the record once the bar is shown (nothing before)."""
        if self.record is not None:
            self.record.update(text, html_body)
