"""Run ``jupyterhub-singleuser`` so that a stop from the hub shuts the student's kernels down first.

LocalProcessSpawner stops a server with SIGINT (then SIGTERM, then SIGKILL). Jupyter Server, run
as JupyterHub's single-user extension without a terminal, treats SIGINT as a KeyboardInterrupt:
it leaves its event loop at once ("Interrupted...") without shutting its kernels down, and each
kernel then notices its parent is gone and exits abruptly, skipping its own clean-up (seen with
JupyterHub 6.1.1 and Jupyter Server 2). The course's child processes then depend on the
kernel-death signal alone. Here SIGINT is turned into SIGTERM, which Jupyter Server handles by
shutting every kernel down properly (each stops its ROS nodes and child processes) before it
exits. Used by classroom/jupyterhub_config.py:

    python classroom/singleuser.py [jupyterhub-singleuser options]
"""

import os
import runpy
import signal
import sys


def _stop_cleanly(_signum, _frame) -> None:
    os.kill(os.getpid(), signal.SIGTERM)  # Jupyter Server's own handler takes it from there


if __name__ == "__main__":
    signal.signal(signal.SIGINT, _stop_cleanly)
    sys.argv[0] = "jupyterhub-singleuser"
    runpy.run_module("jupyterhub.singleuser", run_name="__main__", alter_sys=True)
