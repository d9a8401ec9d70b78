"""The ``%ros2`` IPython magic: ``%ros2 topic list -t`` in a notebook cell, like ``ros2`` in a shell.

Chapters 01-10 use it (01 nodes, 03 topics, 04 services, 05 actions, 06 parameters,
08 the QoS flags). ``get_runtime()`` registers it in a notebook; elsewhere use
``%load_ext course_helpers.notebook.magics``. The commands themselves live in
:mod:`course_helpers.notebook.ros2cli`.

* ``%ros2 <command> ...`` runs one command (line magic);
* ``%%ros2`` runs one command per line of the cell (blank lines and ``#`` comments skipped).

The line is passed as typed: IPython's ``{var}``/``$var`` expansion is off, so YAML
values such as ``"{linear: {x: 0.5}}"`` arrive intact.
"""

from __future__ import annotations

from IPython.core.magic import Magics, line_cell_magic, magics_class, no_var_expand

from course_helpers.notebook import ros2cli


@magics_class
class Ros2Magics(Magics):
    """Holds the ``%ros2`` / ``%%ros2`` magic."""

    @no_var_expand
    @line_cell_magic
    def ros2(self, line: str, cell: str | None = None) -> None:
        """Run ros2 commands against the live graph: ``%ros2 node list``, ``%ros2 topic echo /chatter``."""
        commands = [line] if line.strip() or cell is None else []
        if cell is not None:
            commands += [text for text in cell.splitlines()
                         if text.strip() and not text.lstrip().startswith("#")]
        for command in commands:
            ros2cli.run(command)


def register_magics(shell) -> None:
    """Register ``%ros2`` in an IPython shell."""
    shell.register_magics(Ros2Magics)
    shell._course_ros2_magics = True


def register_once() -> None:
    """Register ``%ros2`` in the running kernel unless it is there (``get_runtime()`` calls this)."""
    from IPython import get_ipython

    shell = get_ipython()
    if shell is not None and not getattr(shell, "_course_ros2_magics", False):
        register_magics(shell)


def load_ipython_extension(ipython) -> None:
    """``%load_ext course_helpers.notebook.magics``."""
    register_magics(ipython)
