"""What the runtime remembers so that, when it heals, it can say which cells to run again.

The runtime heals when its context was shut down from outside (``rclpy.shutdown(context=rt.context)``,
or an interrupt while an rclpy signal handler that the student installed on purpose was active):
it stops what is left and starts afresh, without the nodes and child processes it had. To say what
was lost and where it came from, it records, for each node and child process, the cell that added
it. Which cell is running is something only the notebook layer knows: it sets
:attr:`Origins.where_called` (in plain Python nothing is recorded, and the notice says so in general
words).
"""

from __future__ import annotations

from collections.abc import Callable

HEALED = "[course] ROS was shut down from outside the course runtime ({cause}). The runtime has restarted"
CAUSE = ("rclpy.shutdown() of its context, or an interrupt while an rclpy signal handler was "
         "installed")


class Origins:
    """The cell that added each node (by full name) and each child process (by label), oldest first."""

    def __init__(self):
        #: returns the cell running now ('In [5] "rt.add(Talker)"'), or None; set by the notebook layer
        self.where_called: Callable[[], str | None] = lambda: None
        self._cells: dict[str, str | None] = {}  # what ('/talker', 'child process relay') -> its cell

    def node_added(self, fqn: str) -> None:
        self._record(fqn)

    def child_started(self, label: str) -> None:
        self._record(_child(label))

    def forget_node(self, fqn: str) -> None:
        self._cells.pop(fqn, None)

    def forget_child(self, label: str) -> None:
        self._cells.pop(_child(label), None)

    def clear(self) -> None:
        """Forget everything (the runtime stopped its nodes and children)."""
        self._cells.clear()

    def _record(self, what: str) -> None:
        self._cells.pop(what, None)  # a re-run moves it to the end
        self._cells[what] = self.where_called()

    def healed_notice(self, nodes: list[str], children: list[str], handler_note: str = "") -> str:
        """One line: ROS was shut down from outside, the runtime restarted, and which cells to run
        again (in the order they last ran).

        Args:
            nodes: full names of the runtime's nodes that the shutdown ended.
            children: labels of the child processes the healing stopped.
            handler_note: a sentence about a removed rclpy signal handler, or ''.
        """
        lost = set(nodes) | {_child(label) for label in children}
        ordered = [what for what in self._cells if what in lost] + sorted(lost - set(self._cells))
        text = HEALED.format(cause=CAUSE)
        if not ordered:
            text += "."
        elif all(self._cells.get(what) is None for what in ordered):
            text += f" without {_listed(ordered)}: run the cells that add them again."
        else:
            by_cell: dict[str, list[str]] = {}
            for what in ordered:
                by_cell.setdefault(self._cells.get(what) or "a cell not recorded", []).append(what)
            cells = [f"{cell} ({', '.join(whats)})" for cell, whats in by_cell.items()]
            text += f"; run again {_listed(cells)}."
        return f"{text} {handler_note}".strip()


def _child(label: str) -> str:
    return f"child process {label}"


def _listed(items: list[str]) -> str:
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]
