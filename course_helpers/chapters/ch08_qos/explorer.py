"""A widget to pick a publisher's and a subscription's policies and read whether they connect."""

from __future__ import annotations

from course_helpers.chapters.ch08_qos.compatibility import compatibility_report
from course_helpers.core.errors import CourseError
from course_helpers.core.qos_dict import DEFAULT_QOS_DICT, qos_from_dict

CHOICES = {
    "reliability": ["reliable", "best_effort"],
    "durability": ["volatile", "transient_local"],
    "deadline_s": [("infinite", 0.0), ("0.1 s", 0.1), ("0.5 s", 0.5), ("1 s", 1.0)],
    "liveliness": ["automatic", "manual_by_topic"],
    "lease_s": [("infinite", 0.0), ("0.5 s", 0.5), ("1 s", 1.0), ("2 s", 2.0)],
    "history": ["keep_last", "keep_all"],
    "depth": [1, 5, 10],
}


def compatibility_explorer(rt, pub: dict | None = None, sub: dict | None = None):
    """An ipywidgets box: pick each side's policies, press the button, read why they (do not) connect.

    ``pub`` and ``sub`` are QoS dicts for the starting choices (the rest is the default profile).
    The verdict is given three ways: the per-policy rule, ``qos_check_compatible``, and a real
    publisher/subscription pair created on the spot (its incompatible-QoS events included).
    """
    import ipywidgets as w

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
    output = w.Output()

    def on_click(_button):
        output.clear_output()
        with output:
            try:
                profiles = [qos_from_dict({k: p.value for k, p in pickers[side].items()})
                            for side in ("pub", "sub")]
                print(compatibility_report(rt, *profiles))
            except CourseError as exc:
                print(f"CourseError: {exc}")

    button.on_click(on_click)
    return w.VBox([w.HBox(columns), button, output])
