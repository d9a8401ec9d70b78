"""The reference solution of an exercise, behind an explicit "show the solution" button.

``show_solution('ch03_topics', 'TiltWarning')`` displays a button; pressing it loads the source
of ``course_helpers.solutions.ch03_topics.TiltWarning`` and shows it. Nothing of the solution is in
the saved notebook, so a reader (or a student) sees it only by asking. The solutions are looked up
by name when the button is pressed: the notebook layer does not depend on ``solutions/``, which
a student release of the course leaves out (the button then says so).
"""

from __future__ import annotations

import html
import importlib
import inspect
import time

from course_helpers.core.errors import CourseError

PACKAGE = "course_helpers.solutions"


def solution_source(module: str, name: str) -> str:
    """The source code of the reference solution ``name`` in ``solutions/<module>.py``.

    Raises :class:`CourseError` if this copy of the course has no such solution.
    """
    if not module.isidentifier() or not all(part.isidentifier() for part in name.split(".")):
        raise CourseError(f"name a solution like show_solution('ch03_topics', 'TiltWarning'), "
                          f"got {module!r}, {name!r}")
    try:
        obj = importlib.import_module(f"{PACKAGE}.{module}")
    except ModuleNotFoundError:
        raise CourseError("the reference solutions are not part of this copy of the course "
                          "(a student release leaves them out); ask your instructor") from None
    for part in name.split("."):
        if not hasattr(obj, part):
            raise CourseError(f"solutions/{module}.py has no {name!r}")
        obj = getattr(obj, part)
    try:
        return inspect.getsource(obj)
    except TypeError:
        raise CourseError(f"solutions/{module}.py: {name!r} is a value, not a function or class; "
                          "name a function or class whose code can be shown") from None


def show_solution(module: str, name: str, label: str = "Show the reference solution"):
    """Display a button that reveals the reference solution ``name`` of ``solutions/<module>.py``."""
    import ipywidgets as w
    from IPython.display import display

    from course_helpers.notebook.widget_errors import owned

    button = w.Button(description=label, icon="eye", layout=w.Layout(width="auto"))
    shown = w.HTML()

    def reveal(_button) -> None:
        try:
            code = solution_source(module, name)
        except CourseError as exc:
            shown.value = f"<p><i>{html.escape(str(exc))}</i></p>"
            return
        shown.value = f"<pre>{html.escape(code)}</pre>"
        button.disabled = True

    button.on_click(reveal)
    box = w.VBox([button, shown])
    bundle = {k: v for k, v in owned(box, label)._repr_mimebundle_().items() if "widget-view" in k}
    note = "Run the notebook and press the button to see the reference solution."
    bundle.update({"text/plain": note, "text/html": f"<p><i>{note}</i></p>"})
    display(bundle, raw=True)
    return box


_passing_reports: dict = {}  # (module, name, the check's code) -> (passing report, when it was checked)


def show_passing_report(check, module: str, name: str, recheck: bool = False):
    """Show, collapsed, what a passing checker report looks like, without showing the solution code.

    ``check`` is called with the reference solution ``name`` of ``solutions/<module>.py`` (for
    example ``check_tilt_warning``, or ``lambda cls: check_x(cls, rt)``) and must return a
    ``CheckReport``. The report is real: the checker runs the reference against real nodes. A
    kernel runs each such check once: running the cell again (the same check of the same
    reference) shows the report it measured, with the time it was measured, instead of spending
    the check's seconds again; ``recheck=True`` runs it anew.
    Displayed inside a closed ``<details>`` element, so a student opens it only when they want to.
    Returns the report, or None when this copy of the course has no solutions (a student release).
    Raises :class:`CourseError` with the report when the reference does not pass.
    """
    from IPython.display import display

    try:
        solution = _solution_object(module, name)
    except CourseError as exc:
        note = f"(A passing report is not available here: {exc}.)"
        display({"text/plain": note, "text/html": f"<p><i>{html.escape(note)}</i></p>"}, raw=True)
        return None
    key = (module, name, _code_key(getattr(check, "__code__", None)) or id(check))
    if key in _passing_reports and not recheck:
        report, checked_at = _passing_reports[key]
        again = (f"checked in this kernel at {checked_at}, shown again; "
                 "show_passing_report(..., recheck=True) checks it anew")
    else:
        report = check(solution)
        if not hasattr(report, "summary"):
            raise CourseError("show_passing_report: the check must return a CheckReport, "
                              f"got {type(report).__name__}")
        if not report.passed:  # never save a failing reference under "what passing looks like"
            raise CourseError(f"the reference solution {module}.{name} did not pass its own checker:\n"
                              f"{report.summary()}")
        _passing_reports[key] = (report, time.strftime("%H:%M:%S"))
        again = None
    title = f"what passing looks like: {report.exercise}"
    text = f"[record] {title}\n{report.summary()}"
    body = (f"<details><summary>{html.escape(title.capitalize())} (the reference solution, checked "
            f"against real nodes; its code stays hidden)</summary>{report._repr_html_()}</details>")
    if again:
        text, body = f"{text}\n({again})", f"{body}<p><i>({html.escape(again)})</i></p>"
    display({"text/plain": text,
             "text/html": f"<div class='course-record' data-record='{html.escape(title, quote=True)}'>"
                          f"{body}</div>"}, raw=True)
    return report


def _code_key(code):
    """What a check's code does, comparable across re-runs of its cell (each run compiles it anew):
    its bytecode, names and constants, nested code included. None for an object without code."""
    if code is None:
        return None
    consts = tuple(_code_key(c) if hasattr(c, "co_code") else repr(c) for c in code.co_consts)
    return (code.co_code, code.co_names, code.co_varnames, code.co_freevars, consts)


def _solution_object(module: str, name: str):
    """The object ``name`` of ``solutions/<module>.py`` (a CourseError says why it is missing)."""
    solution_source(module, name)  # validates the names and says why a solution is missing
    obj = importlib.import_module(f"{PACKAGE}.{module}")
    for part in name.split("."):
        obj = getattr(obj, part)
    return obj
