"""The other course kernels of this user, and the line that names those of the same Jupyter server.

Each notebook open in JupyterLab has a kernel of its own, and a course kernel's nodes and child
processes run until that kernel is shut down, whichever notebook the student is looking at. They
share the machine's CPU (and a lab's measurements feel it), and JupyterLab's Running panel is where
they are shut down. So when a runtime starts in a notebook it names them in one line
(:func:`notice`), and ``rt.status()`` lists them.

What counts as one, decided only by what another user cannot forge:

* a process of this user other than this one,
* that holds a course domain's reservation (:mod:`.domains`), which a course runtime takes when it
  starts, and holds until its process exits;
* started by the same parent as this kernel (:func:`other_kernels`'s default): the kernels of one
  Jupyter server (or of one JupyterHub single-user server) are all its children, as the Running
  panel lists them. With ``machine_wide=True`` the kernels of every other server and test process
  of this user count too: what competes with a measurement for the CPU (the QoS lab's busy note).

Its notebook's name comes from ``JPY_SESSION_NAME``, which the Jupyter server sets for each
kernel; its child processes are its children whose ``COURSE_PARENT_PID`` names it (the process layer
sets it). In the default scope, kernels of other servers do not count: the nbval kernels of
parallel test workers, for one, are each a child of its own worker.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from course_helpers.core.domains import domains_held_by
from course_helpers.core.supervisor import PARENT_ENV

SESSION_ENV = "JPY_SESSION_NAME"  # the notebook a Jupyter server started a kernel for


@dataclass(frozen=True)
class OtherKernel:
    """A process of this Jupyter server, other than this one, with a course runtime."""

    pid: int
    name: str  # its notebook's file name; 'a kernel' or 'a process' if its server did not say
    domains: tuple[int, ...]  # the course domains it holds
    children: tuple[int, ...]  # PIDs of the course child processes it runs

    def describe(self) -> str:
        """'03_topics.ipynb (pid 4242 in domain 17 with 2 child processes)'."""
        domains = f"domain{'s' if len(self.domains) > 1 else ''} {' and '.join(map(str, self.domains))}"
        text = f"{self.name} (pid {self.pid} in {domains}"
        count = len(self.children)
        if count:
            text += f" with {count} child process{'es' if count > 1 else ''}"
        return text + ")"


def other_kernels(machine_wide: bool = False) -> list[OtherKernel]:
    """The other course kernels of this user, by PID: those started by this process's parent (its
    Jupyter server), or with ``machine_wide`` those of every server and test process on the machine."""
    import psutil

    me = psutil.Process()
    if machine_wide:
        candidates = psutil.process_iter()
    else:
        try:
            parent = me.parent()
            candidates = parent.children() if parent is not None else []
        except psutil.Error:
            return []
    uid = os.getuid()
    found = []
    for proc in candidates:
        if proc.pid == me.pid:
            continue
        try:
            if proc.uids().real != uid:
                continue
            domains = domains_held_by(proc)
            if not domains:
                continue
            name = (os.path.basename(proc.environ().get(SESSION_ENV, ""))
                    or ("a kernel" if any("ipykernel" in part for part in proc.cmdline()) else "a process"))
            children = tuple(sorted(child.pid for child in proc.children() if _started_by(child, proc.pid)))
        except psutil.Error:  # it ended while we looked, or may not be inspected
            continue
        found.append(OtherKernel(proc.pid, name, tuple(domains), children))
    return sorted(found, key=lambda kernel: kernel.pid)


def _started_by(child, pid: int) -> bool:
    import psutil

    try:
        return child.environ().get(PARENT_ENV) == str(pid)
    except psutil.Error:
        return False


def notice(kernels: list[OtherKernel]) -> str | None:
    """One line naming the other notebooks that run ROS and how to shut them down, or None."""
    if not kernels:
        return None
    names = "; ".join(kernel.describe() for kernel in kernels)
    many = len(kernels) > 1
    return (f"[course] {len(kernels)} other notebook{'s' if many else ''} of this Jupyter server "
            f"{'run' if many else 'runs'} ROS: {names}. Their nodes share this machine's CPU and can slow "
            "what this notebook measures: shut them down with rt.shutdown_other_kernels() (in a notebook, "
            "the button below), or those you are not using in JupyterLab's Running panel (left bar).")
