"""Route prints, logs and errors from node callbacks to the cell that caused them.

Inside Jupyter each node gets a console: a display under the cell that added it. Callbacks run in
the runtime's background thread, and whatever they print or log goes to the node's console instead
of the running cell's own output. Each line shows under the cell during which it was written: when
a node writes while a later cell runs, its console gets a new display under that cell, so a cell
that calls a service shows the server's log line, and the cell that added the server keeps only its
own lines. Lines written while no cell runs go under the cell that ran last (where Jupyter shows any
late output).

At the end of every cell the consoles take in the log lines still on their way through ``/rosout``,
then show what the cell caused: a cell's consoles are complete when the cell is. A console's new
display in a later cell is created at that moment, after the cell's own outputs and in the order the
consoles were opened, so where it stands never depends on timing (strict nbval compares the order of
a cell's outputs); from then on it updates live. Outside Jupyter (tests, scripts) output goes to the
terminal as usual.
"""

from __future__ import annotations

import sys
import threading
import time
import traceback
import uuid
from collections.abc import Callable
from html import escape as html_escape

MAX_LINES = 200  # lines a console keeps; older lines scroll away
FLUSH_PERIOD_S = 0.2  # how often consoles are refreshed in the browser


def in_jupyter_kernel() -> bool:
    """True when running inside an IPython kernel (a notebook), False in plain Python."""
    shell = sys.modules.get("IPython") and sys.modules["IPython"].get_ipython()
    return bool(shell) and hasattr(shell, "kernel")


class Cell:
    """One run of a notebook cell; ``header`` is its execute request's header (what routes output)."""

    __slots__ = ("header", "ended")

    def __init__(self, header: dict | None):
        self.header = dict(header or {})
        self.ended = False  # the cell's code has run and its consoles have been shown


def running_cell() -> Cell:
    """The cell the kernel runs now (or ran last), read from the kernel's display publisher."""
    from IPython import get_ipython

    publisher = getattr(get_ipython(), "display_pub", None)
    return Cell(getattr(publisher, "parent_header", None))


def publish(bundle: dict, display_id: str, cell: Cell | None, update: bool) -> None:
    """Show (or update) a display with an ID under ``cell``, from whichever thread calls.

    ipykernel sends a display with the parent header of the request it handles last, which is not
    the console's cell when a cell has started or a widget has talked since; setting the parent for
    this thread only (ipykernel's ``set_thread_parent``) sends it to the cell it belongs to.
    """
    from IPython import get_ipython
    from IPython.display import display

    publisher = getattr(get_ipython(), "display_pub", None)
    set_parent = getattr(publisher, "set_thread_parent", None)
    token = set_parent(cell.header) if set_parent is not None and cell is not None and cell.header else None
    try:
        display(bundle, raw=True, display_id=display_id, update=update)
    finally:
        if token is not None:
            publisher.reset_thread_parent(token)


class _Part:
    """What one console shows under one cell: a display of its own and the lines of that cell."""

    __slots__ = ("cell", "display_id", "lines", "shown", "dirty")

    def __init__(self, cell: Cell | None, show: bool):
        self.cell = cell
        self.display_id = uuid.uuid4().hex if show else None
        self.lines: list[str] = []
        self.shown = False  # its display exists (later flushes update it)
        self.dirty = False  # it holds lines its display does not show yet


class NodeConsole:
    """The text console of one node, shown under the cells during which the node wrote.

    Each part is a display with an ID: the lines a node prints or logs while a cell runs replace its
    content a few times a second, so it is live in JupyterLab, and the saved notebook keeps the lines
    as plain text and HTML that any notebook viewer shows. A part with no lines shows nothing.
    ``cell_now`` says which cell is running (or ran last); lines written during another cell than
    the last part's start a new part under that cell. A new part's display is created when its
    cell ends (``flush_to_widget(new_parts=True)``), or by any flush once that cell has ended.
    """

    def __init__(self, title: str, show: bool = True, cell_now: Callable[[], Cell | None] = lambda: None):
        self.title = title
        self.show = show
        self._cell_now = cell_now
        self._recent: list[str] = []  # the node's last lines, whichever cell they came in
        self._partial = ""
        self._part: _Part | None = None  # the part lines go to now
        self._unflushed: list[_Part] = []  # earlier parts with lines their displays do not show yet
        self._lock = threading.Lock()  # guards the lines and parts
        self._publishing = threading.Lock()  # keeps a part's display before its updates

    @property
    def display_id(self) -> str | None:
        """The ID of the display that the console's newest lines go to (None when hidden)."""
        return self._part.display_id if self._part is not None else None

    def write(self, text: str) -> None:
        """Append printed text to the running cell's part; complete lines are kept, the oldest dropped."""
        with self._lock:
            pieces = (self._partial + text).split("\n")
            self._partial = pieces.pop()
            self._add(pieces)

    def write_line(self, line: str) -> None:
        """Append a whole line (a log line), ahead of a printed line that is not complete yet."""
        with self._lock:
            self._add([line])

    def _add(self, lines: list[str]) -> None:
        part = self._part_for(self._cell_now())
        for kept in (part.lines, self._recent):
            kept.extend(lines)
            del kept[:-MAX_LINES]
        part.dirty = True

    def show_here(self) -> None:
        """Show the console under the running cell now, empty until the node writes something."""
        with self._lock:
            self._part_for(self._cell_now())
        self.flush_to_widget(new_parts=True, show_empty=True)

    def empty_bundle(self) -> dict:
        """What a part shows while its node has written nothing: nothing visible."""
        return {"text/plain": "",
                "text/html": f"<div class='course-console' data-console='{self._name()}'></div>"}

    def bundle(self, text: str) -> dict:
        """Lines as plain text and HTML (what a saved notebook shows); no lines, the empty bundle."""
        if not text:
            return self.empty_bundle()
        html = (f"<div class='course-console' data-console='{self._name()}'>"
                f"<small>console of {self._name()}</small>"
                f"<pre style='max-height:10em;overflow:auto;margin:0'>{html_escape(text)}</pre></div>")
        return {"text/plain": f"console of {self.title}:\n{text}", "text/html": html}

    def flush_to_widget(self, new_parts: bool = False, show_empty: bool = False) -> None:
        """Show each part's new lines under its cell.

        A part without a display yet gets one only if ``new_parts`` is set or its cell has ended
        (otherwise it waits); ``show_empty`` shows the newest part even without lines.
        """
        with self._publishing:
            with self._lock:
                parts = self._unflushed + ([self._part] if self._part is not None else [])
                due, self._unflushed = [], []
                for part in parts:
                    if part.display_id is None or not (part.dirty or (show_empty and not part.shown)):
                        continue
                    if not (part.shown or new_parts or (part.cell is not None and part.cell.ended)):
                        if part is not self._part:
                            self._unflushed.append(part)
                        continue
                    lines = part.lines + ([self._partial] if part is self._part and self._partial else [])
                    due.append((part, "\n".join(lines), part.shown))
                    part.dirty, part.shown = False, True
            for part, text, shown in due:
                publish(self.bundle(text), part.display_id, part.cell, update=shown)

    def text(self) -> str:
        """The node's most recent lines (at most MAX_LINES), whichever cells they showed under."""
        with self._lock:
            return "\n".join(self._recent + ([self._partial] if self._partial else []))

    def _part_for(self, cell: Cell | None) -> _Part:
        if self._part is None or self._part.cell is not cell:
            if self._part is not None and self._part.dirty:
                self._unflushed.append(self._part)
            self._part = _Part(cell, self.show)
        return self._part

    def _name(self) -> str:
        return html_escape(self.title, quote=True)


class _ThreadRoutedStream:
    """A stand-in for ``sys.stdout``/``sys.stderr``: writes from a routed thread go to a console."""

    def __init__(self, original, local: threading.local):
        self._original = original
        self._local = local

    def write(self, text):
        console = getattr(self._local, "console", None)
        if console is None:
            return self._original.write(text)
        console.write(text)
        return len(text)

    def flush(self):
        if getattr(self._local, "console", None) is None:
            self._original.flush()

    def __getattr__(self, name):
        return getattr(self._original, name)


class ConsoleRouter:
    """Owns the consoles, the thread-local switch the executor flips per callback, and which cell runs.

    It follows the kernel's cells through IPython's ``pre_run_cell`` and ``post_run_cell`` events.
    At the end of a cell it calls ``sync_logs`` (set by the runtime: it returns once every line
    logged so far has come through ``/rosout``) and then shows every console's new lines, so they
    reach the notebook before the kernel reports the cell done. A console closed during a cell
    (its node removed) is shown with the others then.
    """

    def __init__(self):
        self._local = threading.local()
        self._consoles: dict[str, NodeConsole] = {}  # logger name -> console
        self._closed: list[NodeConsole] = []  # consoles closed since the last cell ended
        self._unclaimed: dict[str, list[str]] = {}  # this cell's log lines of nodes without a console yet
        self._lock = threading.Lock()  # guards the three above
        self._cell: Cell | None = None  # the cell running now, or the last one that ran
        self._hooked = None  # the shell whose cell events we follow
        self.sync_logs: Callable[[], object] | None = None
        self._stop = threading.Event()
        self._flusher: threading.Thread | None = None
        self._streams = None

    def start(self) -> None:
        """Wrap sys.stdout/sys.stderr, follow the kernel's cells and start refreshing consoles."""
        if self._streams is None:
            self._streams = (sys.stdout, sys.stderr)
            sys.stdout = _ThreadRoutedStream(sys.stdout, self._local)
            sys.stderr = _ThreadRoutedStream(sys.stderr, self._local)
        if self._hooked is None:
            from IPython import get_ipython

            self._hooked = get_ipython()
            self._hooked.events.register("pre_run_cell", self._cell_starts)
            self._hooked.events.register("post_run_cell", self._cell_ends)
            self._cell = running_cell()  # started from a cell, after its pre_run_cell
        if self._flusher is not None and self._flusher.is_alive():
            return  # one flusher per router, however often the runtime starts
        self._stop.clear()
        self._flusher = threading.Thread(
            target=self._flush_loop, name="course-console", daemon=True
        )
        self._flusher.start()

    def stop(self) -> None:
        """Put the original streams back, stop following cells and stop refreshing."""
        self._stop.set()
        if self._flusher is not None:
            self._flusher.join(timeout=2)
            self._flusher = None
        self._flush_all(new_parts=True)  # stopped from a cell: what the consoles hold shows here
        if self._hooked is not None:
            for event, callback in (("pre_run_cell", self._cell_starts), ("post_run_cell", self._cell_ends)):
                try:
                    self._hooked.events.unregister(event, callback)
                except ValueError:  # already gone
                    pass
            self._hooked = None
        with self._lock:
            self._unclaimed.clear()
            self._closed.clear()
        if self._streams is not None:
            if isinstance(sys.stdout, _ThreadRoutedStream):
                sys.stdout = self._streams[0]
            if isinstance(sys.stderr, _ThreadRoutedStream):
                sys.stderr = self._streams[1]
            self._streams = None

    def open(self, logger_name: str, title: str, show: bool = True) -> NodeConsole:
        """Create (or replace) the console for a logger name and show it in the current cell.

        Lines the node logged in this cell before it had a console (in its constructor) go into it.
        """
        console = NodeConsole(title, show, self._cell_now)
        with self._lock:
            self._consoles[logger_name] = console
            for line in self._unclaimed.pop(logger_name, []):
                console.write_line(line)
        if show:
            console.show_here()
        return console

    def close(self, logger_name: str) -> None:
        """Forget a console once the lines its node logged so far are in (its displays keep them)."""
        if logger_name in self._consoles:
            self._sync_logs()
        with self._lock:
            console = self._consoles.pop(logger_name, None)
            if console is not None:
                self._closed.append(console)
        if console is not None:
            console.flush_to_widget()  # its displays so far; a new one waits for the cell's end

    def console_for(self, logger_name: str) -> NodeConsole | None:
        """The console of a logger name, if it has one."""
        return self._consoles.get(logger_name)

    def enter(self, console: NodeConsole | None) -> None:
        """Route this thread's prints to ``console`` (None: back to the cell's own output)."""
        self._local.console = console

    def write_log(self, logger_name: str, line: str) -> bool:
        """Append a log line to the console of ``logger_name``; False if it has none (yet)."""
        with self._lock:
            console = self._consoles.get(logger_name)
            if console is None:
                kept = self._unclaimed.setdefault(logger_name, [])
                kept.append(line)
                del kept[:-MAX_LINES]
                return False
            console.write_line(line)
        return True

    def write_error(self, console: NodeConsole | None, where: str, exc: BaseException) -> None:
        """Show a callback's exception in its console (or on stderr) without stopping ROS."""
        text = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
        message = f"[callback error in {where}] {text}"
        if console is not None:
            console.write(message)
        else:
            self._cell_stderr().write(message)

    def write_internal_error(self, where: str, exc: BaseException, log_path: str) -> None:
        """The course's own thread failed: append the traceback to ``log_path`` and show one line.

        A student can do nothing with a traceback through the course's internals; the line names
        the error and the file that holds the details.
        """
        text = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
        with open(log_path, "a", encoding="utf-8") as log:
            log.write(f"--- {time.strftime('%H:%M:%S')} in {where}\n{text}")
        first = str(exc).splitlines()[0] if str(exc) else ""
        self._cell_stderr().write(f"[course] internal error in {where}: {type(exc).__name__}"
                                  f"{': ' + first if first else ''} (traceback in {log_path})\n")

    def _cell_stderr(self):
        """The stderr of whatever cell runs (never a node console)."""
        return self._streams[1] if self._streams else sys.__stderr__

    def _cell_now(self) -> Cell | None:
        return self._cell

    def _cell_starts(self, info=None) -> None:
        if self._cell is not None:
            self._cell.ended = True
        self._cell = running_cell()
        with self._lock:
            self._unclaimed.clear()  # lines of nodes that never got a console belong to no cell now

    def _cell_ends(self, result=None) -> None:
        if any(console.show for console in self._all()):
            self._sync_logs()
        self._flush_all(new_parts=True)
        with self._lock:
            self._closed.clear()
        if self._cell is not None:
            self._cell.ended = True

    def _sync_logs(self) -> None:
        if self.sync_logs is not None:
            try:
                self.sync_logs()
            except Exception:  # the context was shut down meanwhile: show what has arrived
                pass

    def _all(self) -> list[NodeConsole]:
        with self._lock:
            return self._closed + list(self._consoles.values())

    def _flush_loop(self) -> None:
        while not self._stop.wait(FLUSH_PERIOD_S):
            self._flush_all()

    def _flush_all(self, new_parts: bool = False) -> None:
        for console in self._all():
            try:
                console.flush_to_widget(new_parts)
            except Exception:  # a closed comm must not stop the other consoles
                pass


def format_log_line(level: int, name: str, text: str, stamp_s: float | None = None) -> str:
    """Format a rosout entry the way ``ros2 run`` prints it on a terminal."""
    names = {10: "DEBUG", 20: "INFO", 30: "WARN", 40: "ERROR", 50: "FATAL"}
    stamp = time.time() if stamp_s is None else stamp_s
    return f"[{names.get(level, level)}] [{stamp:.3f}] [{name}]: {text}"
