"""A course widget's callback error, shown as one line in the cell that displayed the widget.

A slider's ``observe`` callback or a button's ``on_click`` runs when the browser sends a change,
long after its cell ended. Left alone, ipywidgets hands such an error to the kernel's log (a button's)
or lets it escape the comm handler (an observer's), and JupyterLab shows it only in its hidden log
console: the widget just seems dead. So every course widget is displayed through :func:`owned`
(``notebook.records.show_with_record`` does it), which puts an error line under the widget and
remembers the cell's number. :func:`install` wraps ipywidgets' one entry for browser messages,
``Widget._handle_msg``, once per kernel: an exception raised while a message is handled (an
observer's, or one a button's dispatcher would print) becomes one line in the owning widget's error
line, saying what happened and, for a node that a later cell destroyed, which cell to run again.
The next message that is handled without an error clears the line.

A course slider sends its value when it is released, not while it moves (``continuous_update`` off):
a slider that sends while it moves also sends when it is first drawn, its value passed through the
browser slider's own arithmetic (5.0 comes back as 5.000000000000001). Under "Run All" that message
reaches the kernel after the later cells ran, and undid what they set (00's rate slider showed 5.00
after the next cell had set 20.0, and retuned a talker that a later cell had destroyed).
"""

from __future__ import annotations

import html
import sys
import weakref

ERROR_CLASS = "course-widget-error"  # the error line's CSS class (the browser tests look for it)
_owners: list[weakref.ref] = []  # every Owner shown in this kernel
_installed = False


class Owner:
    """A displayed course widget: its tree's root, its error line, its title and its cell's number.

    The error line goes under ``widget`` in a new box, or with ``inside=True`` at the end of ``widget``'s
    own children (a box the course built, such as the live graph's)."""

    def __init__(self, widget, title: str, cell: int | None, inside: bool = False):
        import ipywidgets as widgets

        self.widget, self.title, self.cell = widget, title, cell
        self.error_line = widgets.HTML("")
        if inside:
            widget.children = (*widget.children, self.error_line)
            self.box = widget
        else:
            self.box = widgets.VBox([widget, self.error_line])

    def holds(self, widget) -> bool:
        """True when ``widget`` is this owner's widget or inside it (a box's children, at any depth)."""
        stack = [self.widget]
        while stack:
            current = stack.pop()
            if current is widget:
                return True
            stack.extend(getattr(current, "children", ()))
        return False

    def show_error(self, line: str) -> None:
        self.error_line.value = (f"<div class='{ERROR_CLASS}' style='color:#a11'>"
                                 f"&#9888; {html.escape(line)}</div>")

    def clear(self) -> None:
        if self.error_line.value:
            self.error_line.value = ""


def owned(widget, title: str, inside: bool = False):
    """``widget`` with an error line under it (an ipywidgets VBox), for display in the current cell;
    with ``inside=True`` the line is added to ``widget``'s own children and ``widget`` is returned."""
    install()
    owner = Owner(widget, title, _cell_number(), inside)
    _owners[:] = [ref for ref in _owners if ref() is not None]
    _owners.append(weakref.ref(owner))
    owner.box._course_owner = owner  # the box keeps its owner alive while it is shown
    for member in _tree(widget):
        comm = getattr(member, "comm", None)
        if comm is not None:  # made before install(): their comms still call the original
            comm.on_msg(member._handle_msg)
        if "Slider" in type(member).__name__ and getattr(member, "continuous_update", False):
            member.continuous_update = False  # no render echo (see the module docstring)
    return owner.box


def _tree(widget):
    yield widget
    for child in getattr(widget, "children", ()):
        yield from _tree(child)


def explain(error: BaseException, title: str, cell: int | None) -> str:
    """One line: which widget, what went wrong, and what to do."""
    where = f"run cell [{cell}] again" if cell else "run its cell again"
    if type(error).__name__ == "InvalidHandle" or "destruction was requested" in str(error):
        return (f"{title}: the node it drives was destroyed by a later cell (rt.remove_all(), or rt.add "
                f"of a node with its name): {where} to make it anew.")
    message = str(error).strip().splitlines()[0] if str(error).strip() else ""
    return f"{title}: {type(error).__name__}" + (f": {message}" if message else "")


def report(widget, error: BaseException) -> str:
    """Show ``error`` of ``widget``'s callback in the cell of the course widget that holds it; the line."""
    for ref in reversed(_owners):
        owner = ref()
        if owner is not None and owner.holds(widget):
            line = explain(error, owner.title, owner.cell)
            owner.show_error(line)
            return line
    line = explain(error, getattr(widget, "description", "") or type(widget).__name__, None)
    print(f"[course] {line}", file=sys.stderr)  # a widget no course cell displayed: one line still
    return line


def install() -> None:
    """Wrap ``ipywidgets.Widget._handle_msg`` once (see the module docstring)."""
    global _installed
    if _installed:
        return
    import ipywidgets

    original = ipywidgets.Widget._handle_msg

    def handle_msg(self, msg):
        caught: list[BaseException] = []
        with _tracebacks_caught(caught):
            try:
                original(self, msg)
            except Exception as error:  # an observer's: it would escape into the comm handler
                caught.append(error)
        errors = [error for error in caught if error is not None]
        if errors:
            report(self, errors[-1])
        elif msg.get("content", {}).get("data", {}).get("method") in ("update", "custom"):
            for ref in _owners:
                owner = ref()
                if owner is not None and owner.holds(self):
                    owner.clear()

    ipywidgets.Widget._handle_msg = handle_msg
    _installed = True


class _tracebacks_caught:
    """While handling one browser message: ``shell.showtraceback()`` (what a button's callback
    dispatcher calls on an error) records the error instead of sending a traceback to nowhere."""

    def __init__(self, caught: list):
        self.caught, self.shell = caught, None

    def __enter__(self):
        from IPython import get_ipython

        self.shell = get_ipython()
        if self.shell is not None:
            self.previous = self.shell.__dict__.get("showtraceback")  # one set on the instance, if any
            self.shell.showtraceback = lambda *_a, **_k: self.caught.append(sys.exc_info()[1])
        return self

    def __exit__(self, *_exc):
        if self.shell is not None:
            if self.previous is None:
                del self.shell.showtraceback  # the class's method again
            else:
                self.shell.showtraceback = self.previous
        return False


def _cell_number() -> int | None:
    """The number of the cell running now (its ``[n]``), or None outside IPython."""
    from IPython import get_ipython

    shell = get_ipython()
    result = getattr(getattr(shell, "displayhook", None), "exec_result", None)  # the running cell's
    return getattr(result, "execution_count", None)
