"""Widgets of the chapter: a mission's progress bar."""

from __future__ import annotations

from course_helpers.chapters.ch10_capstone.missions import Mission


def mission_progress(mission: Mission):
    """A progress bar and a label that follow a :class:`.missions.Mission` as its feedback arrives.

    Returns: the widget; its plain-text form is a fixed label, so notebook outputs stay comparable.
    """
    import ipywidgets as widgets

    bar = widgets.FloatProgress(value=mission.progress, min=0.0, max=1.0,
                                description=f"{mission.item_id}", bar_style="info",
                                layout=widgets.Layout(width="420px"))
    label = widgets.Label(value=mission.state)

    def follow(m: Mission) -> None:
        bar.value = m.progress
        label.value = m.state
        if m.finished:
            bar.bar_style = "success" if m.success else "danger"

    mission.listeners.append(follow)
    follow(mission)
    return _labelled_box([bar, label], f"progress of mission {mission.item_id}@{mission.shelf}")


def _labelled_box(children, text: str):
    """An HBox whose plain-text form is a fixed label (notebook outputs stay comparable)."""
    import ipywidgets as widgets

    class LabelledBox(widgets.HBox):
        def __repr__(self) -> str:
            return f"<{text}>"

    return LabelledBox(children)
