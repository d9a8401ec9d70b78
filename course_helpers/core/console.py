"""Route prints, logs and errors from node callbacks to the cell that started the node.

Inside Jupyter each node gets a small console under the cell that added it; callbacks run in
the runtime's background thread, and whatever they print lands in that console instead of
whatever cell happens to be running. Outside Jupyter (tests, scripts) output goes to the
terminal as usual.
"""

from __future__ import annotations

import sys
import threading
import time
import traceback
import uuid
from html import escape as html_escape

from course_helpers.core.callback_errors import RepeatCounter

MAX_LINES = 200  # lines a console keeps; older lines scroll away
FLUSH_PERIOD_S = 0.2  # how often consoles are refreshed in the browser


def in_jupyter_kernel() -> bool:
    """True when running inside an IPython kernel (a notebook), False in plain Python."""
    shell = sys.modules.get("IPython") and sys.modules["IPython"].get_ipython()
    return bool(shell) and hasattr(shell, "kernel")


class NodeConsole:
    """The text console of one node, shown under the cell that started it.

    It is a display with an ID: the lines a node prints or logs replace its content a few times a
    second, so it is live in JupyterLab, and the saved notebook keeps the last lines as plain text
    and HTML that any notebook viewer shows; its header says they include what later cells made the
    node do (a server's console shows the requests of the cells below it). Until the node logs
    something it shows nothing.
    """

    def __init__(self, title: str, show: bool = True):
        self.title = title
        self.display_id = uuid.uuid4().hex if show else None
        self._lines: list[str] = []
        self._partial = ""
        self._dirty = False
        self._lock = threading.Lock()

    def write(self, text: str) -> None:
        """Append text; complete lines are kept, the oldest dropped past MAX_LINES."""
        with self._lock:
            pieces = (self._partial + text).split("\n")
            self._partial = pieces.pop()
            self._lines.extend(pieces)
            del self._lines[:-MAX_LINES]
            self._dirty = True

    def empty_bundle(self) -> dict:
        """What the console shows before its node logs anything: nothing visible."""
        return {"text/plain": "",
                "text/html": f"<div class='course-console' data-console='{self._name()}'></div>"}

    def bundle(self, text: str) -> dict:
        """The console's lines as plain text and HTML (what a saved notebook shows)."""
        html = (f"<div class='course-console' data-console='{self._name()}'>"
                f"<small>console of {self._name()}: all it logged while the notebook ran, "
                "what later cells made it do included</small>"
                f"<pre style='max-height:10em;overflow:auto;margin:0'>{html_escape(text)}</pre></div>")
        return {"text/plain": f"console of {self.title}:\n{text}", "text/html": html}

    def flush_to_widget(self) -> None:
        """Show the buffered lines under the node's cell if anything changed."""
        with self._lock:
            if not self._dirty or self.display_id is None:
                return
            text = "\n".join(self._lines + ([self._partial] if self._partial else []))
            self._dirty = False
        from IPython.display import update_display

        update_display(self.bundle(text), display_id=self.display_id, raw=True)

    def text(self) -> str:
        """Everything the console currently holds."""
        with self._lock:
            return "\n".join(self._lines + ([self._partial] if self._partial else []))

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
    """Owns the consoles and the thread-local switch the executor flips per callback."""

    def __init__(self):
        self._local = threading.local()
        self._consoles: dict[str, NodeConsole] = {}  # logger name -> console
        self._stop = threading.Event()
        self._flusher: threading.Thread | None = None
        self._streams = None
        self._callback_errors = RepeatCounter()

    def start(self) -> None:
        """Wrap sys.stdout/sys.stderr and start refreshing consoles."""
        if self._streams is None:
            self._streams = (sys.stdout, sys.stderr)
            sys.stdout = _ThreadRoutedStream(sys.stdout, self._local)
            sys.stderr = _ThreadRoutedStream(sys.stderr, self._local)
        if self._flusher is not None and self._flusher.is_alive():
            return  # one flusher per router, however often the runtime starts
        self._stop.clear()
        self._flusher = threading.Thread(
            target=self._flush_loop, name="course-console", daemon=True
        )
        self._flusher.start()

    def stop(self) -> None:
        """Put the original streams back and stop refreshing."""
        self._stop.set()
        if self._flusher is not None:
            self._flusher.join(timeout=2)
            self._flusher = None
        self._flush_all()
        if self._streams is not None:
            if isinstance(sys.stdout, _ThreadRoutedStream):
                sys.stdout = self._streams[0]
            if isinstance(sys.stderr, _ThreadRoutedStream):
                sys.stderr = self._streams[1]
            self._streams = None

    def open(self, logger_name: str, title: str, show: bool = True) -> NodeConsole:
        """Create (or replace) the console for a logger name and display it in the current cell."""
        console = NodeConsole(title, show)
        self._consoles[logger_name] = console
        if show:
            from IPython.display import display

            display(console.empty_bundle(), raw=True, display_id=console.display_id)
        return console

    def close(self, logger_name: str) -> None:
        """Forget a console (its widget keeps what it showed)."""
        console = self._consoles.pop(logger_name, None)
        if console is not None:
            console.flush_to_widget()

    def console_for(self, logger_name: str) -> NodeConsole | None:
        """The console of a logger name, if it has one."""
        return self._consoles.get(logger_name)

    def enter(self, console: NodeConsole | None) -> None:
        """Route this thread's prints to ``console`` (None: back to the cell's own output)."""
        self._local.console = console

    def write_log(self, logger_name: str, line: str) -> bool:
        """Append a log line to the console of ``logger_name``; False if it has none."""
        console = self._consoles.get(logger_name)
        if console is None:
            return False
        console.write(line + "\n")
        return True

    def write_error(self, console: NodeConsole | None, where: str, exc: BaseException) -> None:
        """Show a callback's exception in its console (and on the cell's stderr when the console is
        hidden) without stopping ROS; a repeat of the same error is counted, not shown again."""
        message = self._callback_errors.report(where, exc)  # the student's frames; repeats counted
        if message is None:
            return
        if console is not None:
            console.write(message)
        if console is None or console.display_id is None:  # no console on the page: the cell says it
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

    def _flush_loop(self) -> None:
        while not self._stop.wait(FLUSH_PERIOD_S):
            self._flush_all()

    def _flush_all(self) -> None:
        for console in list(self._consoles.values()):
            try:
                console.flush_to_widget()
            except Exception:  # a closed comm must not stop the other consoles
                pass


def format_log_line(level: int, name: str, text: str, stamp_s: float | None = None) -> str:
    """Format a rosout entry the way ``ros2 run`` prints it on a terminal."""
    names = {10: "DEBUG", 20: "INFO", 30: "WARN", 40: "ERROR", 50: "FATAL"}
    stamp = time.time() if stamp_s is None else stamp_s
    return f"[{names.get(level, level)}] [{stamp:.3f}] [{name}]: {text}"
