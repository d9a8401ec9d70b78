"""Widgets of the chapter: a mission's progress bar, with a static record of how the mission went."""

from __future__ import annotations

import html

from course_helpers.chapters.ch10_capstone.missions import Mission


def mission_summary(mission: Mission) -> str:
    """The mission as text: its title and state, then one line per step so far."""
    lines = [f"mission {mission.item_id}@{mission.shelf}: {mission.state} "
             f"(progress {mission.progress:.0%})"]
    lines += [f"  - {step}" for step in mission.steps]
    return "\n".join(lines)


def mission_html(mission: Mission) -> str:
    """The mission as HTML: a progress bar, the state and the steps."""
    colour = {True: "#2e7d32", False: "#c62828"}.get(mission.success, "#555")
    steps = "".join(f"<li>{html.escape(step)}</li>" for step in mission.steps)
    return (f"<progress value='{mission.progress:.3f}' max='1'></progress> "
            f"<b style='color:{colour}'>{html.escape(mission.state)}</b><ol>{steps}</ol>")


def mission_progress(mission: Mission):
    """Display a progress bar and a label that follow a :class:`.missions.Mission` as its feedback
    arrives, with a static record (``notebook.records``) of the mission's steps, filled in when it ends.

    Returns: the widget (an ipywidgets HBox). Assign it (``bar = mission_progress(m)``), so that the
    cell does not display it a second time.
    """
    import ipywidgets as widgets

    from course_helpers.notebook.records import show_with_record

    bar = widgets.FloatProgress(value=mission.progress, min=0.0, max=1.0,
                                description=f"{mission.item_id}", bar_style="info",
                                layout=widgets.Layout(width="420px"))
    label = widgets.Label(value=mission.state)
    box = widgets.HBox([bar, label])
    record = show_with_record(box, f"mission {mission.item_id}@{mission.shelf}", mission_summary(mission),
                              mission_html(mission))

    def follow(m: Mission) -> None:
        bar.value = m.progress
        label.value = m.state
        if m.success is not None:  # set by the runner just before its last update
            bar.bar_style = "success" if m.success else "danger"
            record.update(mission_summary(m), mission_html(m))

    mission.listeners.append(follow)
    follow(mission)
    return box
