"""Widgets that leave a static record: live in JupyterLab, readable in any saved copy.

A widget's saved output holds only what a renderer without widget support can show: its text
form, which for an ipywidgets box is a bare repr such as ``HBox(children=(...))``. ``show_with_record``
displays the widget together with a text and HTML record under one display ID; ``Record.update``
replaces the record (for instance when a run ends, with a picture of the final plot). JupyterLab
shows the live widget; GitHub, nbviewer and the course website show the record. nbval does not
compare records (``tests/nbval_sanitize.cfg``), since the saved one is the final state. An error in
the widget's callbacks shows as one line under it (:mod:`.widget_errors`).
"""

from __future__ import annotations

import base64
import html
import io
import uuid

WIDGET_MIME = "application/vnd.jupyter.widget-view+json"


def figure_html(figure, dpi: int = 80) -> str:
    """An ``<img>`` tag holding a matplotlib figure as an inline PNG (no file beside the notebook)."""
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight")
    encoded = base64.b64encode(buffer.getvalue()).decode("ascii")
    return f"<img alt='the final plot' style='max-width:100%' src='data:image/png;base64,{encoded}'>"


class Record:
    """The static record shown beside a widget; :meth:`update` replaces it."""

    def __init__(self, widget, title: str, text: str, html_body: str | None = None):
        from course_helpers.notebook.widget_errors import owned

        self.widget = owned(widget, title)  # with a line for its callbacks' errors (widget_errors)
        self.title = title
        self.display_id = uuid.uuid4().hex
        self._bundle = self._make(text, html_body)

    def _make(self, text: str, html_body: str | None, figure=None) -> dict:
        body = html_body if html_body is not None else f"<pre>{html.escape(text)}</pre>"
        if figure is not None:
            body += figure_html(figure)
        name = html.escape(self.title, quote=True)
        bundle = {"text/plain": f"[record] {self.title}\n{text}",
                  "text/html": f"<div class='course-record' data-record='{name}'>{body}</div>"}
        view = getattr(self.widget, "_repr_mimebundle_", None)
        if view is not None:
            bundle.update({k: v for k, v in view().items() if k == WIDGET_MIME})
        return bundle

    def show(self) -> Record:
        """Display the widget with its record (in the cell that calls this)."""
        from IPython.display import display

        display(self._bundle, raw=True, display_id=self.display_id)
        return self

    def update(self, text: str, html_body: str | None = None, figure=None) -> None:
        """Replace the record: ``text`` for plain-text readers, ``html_body`` (or ``text``) and an
        optional matplotlib ``figure`` for HTML readers. The live widget stays as it is."""
        from IPython.display import update_display

        self._bundle = self._make(text, html_body, figure)
        update_display(self._bundle, display_id=self.display_id, raw=True)


def show_with_record(widget, title: str, text: str, html_body: str | None = None) -> Record:
    """Display ``widget`` with a static record titled ``title``; returns the :class:`Record`."""
    return Record(widget, title, text, html_body).show()
