"""A widget to pick a publisher's and a subscription's policies and read whether they connect.

The explorer checks its starting choices at once, and again on every press of its button. Its
static record (``course_helpers.notebook.records``) holds the last report it showed and one line
per check, so a saved copy of the notebook shows what the explorer showed.
"""

from __future__ import annotations

import html

from course_helpers.chapters.ch08_qos.compatibility import compatibility_report, compatible
from course_helpers.core.errors import CourseError
from course_helpers.core.qos_dict import DEFAULT_QOS_DICT, describe_qos, qos_from_dict

RECORD_TITLE = "QoS compatibility explorer"
CHOICES = {
    "reliability": ["reliable", "best_effort"],
    "durability": ["volatile", "transient_local"],
    "deadline_s": [("infinite", 0.0), ("0.1 s", 0.1), ("0.5 s", 0.5), ("1 s", 1.0)],
    "liveliness": ["automatic", "manual_by_topic"],
    "lease_s": [("infinite", 0.0), ("0.5 s", 0.5), ("1 s", 1.0), ("2 s", 2.0)],
    "history": ["keep_last", "keep_all"],
    "depth": [1, 5, 10],
}


class _Checks:
    """What the explorer has shown: every check as one line, and the last full report."""

    def __init__(self):
        self.lines: list[str] = []
        self.last_report = ""

    def add(self, pub, sub, report_text: str) -> None:
        verdict = "connect" if compatible(pub, sub) else "do NOT connect"
        self.lines.append(f"{len(self.lines) + 1}. publisher {describe_qos(pub)} | subscription "
                          f"{describe_qos(sub)} -> they {verdict}")
        self.last_report = report_text

    def text(self) -> str:
        return ("Checks made:\n" + "\n".join(self.lines) + "\n\nThe last report:\n" + self.last_report)

    def html(self) -> str:
        items = "".join(f"<li>{html.escape(line.split('. ', 1)[1])}</li>" for line in self.lines)
        return (f"<b>{RECORD_TITLE}</b>: the checks made<ol>{items}</ol>"
                f"<p>The last report:</p><pre>{html.escape(self.last_report)}</pre>")


def compatibility_explorer(rt, pub: dict | None = None, sub: dict | None = None):
    """Display an ipywidgets box: pick each side's policies, press the button, read why they (do not)
    connect. Returns the :class:`~course_helpers.notebook.records.Record` shown with it.

    ``pub`` and ``sub`` are QoS dicts for the starting choices (the rest is the default profile),
    which are checked at once. The verdict is given three ways: the per-policy rule,
    ``qos_check_compatible``, and a real publisher/subscription pair created on the spot (its
    incompatible-QoS events included).
    """
    import ipywidgets as w

    from course_helpers.notebook.records import show_with_record

    start = {"pub": {**DEFAULT_QOS_DICT, **(pub or {})}, "sub": {**DEFAULT_QOS_DICT, **(sub or {})}}
    pickers: dict[str, dict] = {"pub": {}, "sub": {}}
    columns = []
    for side, title in (("pub", "Publisher offers"), ("sub", "Subscription requests")):
        boxes = [w.HTML(f"<b>{title}</b>")]
        for key, options in CHOICES.items():
            picker = w.Dropdown(options=options, value=start[side][key], description=key.replace("_s", ""),
                                layout=w.Layout(width="260px"))
            pickers[side][key] = picker
            boxes.append(picker)
        columns.append(w.VBox(boxes))
    button = w.Button(description="Check (live pair)", button_style="primary")
    shown = w.HTML()
    checks = _Checks()

    def check(_button=None) -> None:
        try:
            profiles = [qos_from_dict({key: picker.value for key, picker in pickers[side].items()})
                        for side in ("pub", "sub")]
            text = compatibility_report(rt, *profiles)
            checks.add(*profiles, text)
        except CourseError as exc:
            text = f"CourseError: {exc}"
        shown.value = f"<pre>{html.escape(text)}</pre>"
        if checks.lines and record is not None:
            record.update(checks.text(), html_body=checks.html())

    record = None
    check()
    record = show_with_record(w.VBox([w.HBox(columns), button, shown]), RECORD_TITLE, checks.text(),
                              checks.html())
    button.on_click(check)
    return record
