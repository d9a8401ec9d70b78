"""Jupyter kernels that several test processes can start at the same moment.

jupyter_client gives a kernel five TCP ports by binding port 0 and letting go of it. Another process
starting a kernel at that moment can be handed the same port, and one of the two kernels dies
("Address already in use"; 1 kernel start in 90, six at a time, on the 2-core development machine, as
when nbval's six workers start their first notebooks). A kernel that listens on Unix sockets in a
folder of its own has nothing to collide on: 0 in 90 the same way.

:class:`PrivateSocketKernelManager` is for code that drives a kernel itself (nbval, the tests);
:class:`AsyncPrivateSocketKernelManager` for nbclient: nbgrader's autograde, the release's run of the
instructor source, ``make execute`` and the tests that run notebooks. Every ``NotebookClient`` of the
repository names it (a test checks).
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import uuid

from jupyter_client.manager import AsyncKernelManager, KernelManager

_folder: list[str] = []  # this process's folder of kernel sockets, made on first use


def _socket_folder() -> str:
    if not _folder:
        _folder.append(tempfile.mkdtemp(prefix="course-kernels-"))
        atexit.register(shutil.rmtree, _folder[0], True)
    return _folder[0]


class _PrivateSockets:
    """Makes a KernelManager's kernel listen on Unix sockets named after a fresh id (jupyter_client's
    ``ipc`` transport), so that no other kernel can take its addresses."""

    def __init__(self, **kwargs):
        kwargs.setdefault("transport", "ipc")
        kwargs.setdefault("ip", os.path.join(_socket_folder(), uuid.uuid4().hex))
        super().__init__(**kwargs)


class PrivateSocketKernelManager(_PrivateSockets, KernelManager):
    """jupyter_client's KernelManager on sockets of its own."""


class AsyncPrivateSocketKernelManager(_PrivateSockets, AsyncKernelManager):
    """jupyter_client's AsyncKernelManager on sockets of its own."""
