# JupyterHub for a class on one Linux host: every student is a Unix user, the course is installed
# once, read-only, and shared. Step-by-step recipe: docs/classroom.md. Run as root:
#
#     jupyterhub -f /opt/ros2-course/classroom/jupyterhub_config.py
#
# What each student gets when they log in:
# * their own single-user Jupyter server, a process running as their Unix user (LocalProcessSpawner),
#   started from the course's venv, which students can run but not change;
# * their own working copy of the notebooks in ~/ros2-course-work, brought up to date with the
#   course at every server start without losing their edits (tools/working_copy.py);
# * a ROS domain of its own for every kernel: the course reserves one machine-wide with an abstract
#   Unix socket per domain (course_helpers/core/domains.py), and discovery stays on this host, so two
#   students' kernels never share a domain. Domains 1-101 are free for the course, so at
#   most about 100 kernels can run at once; idle kernels are shut down (below) to give theirs back.
#
# Settings come from the environment, so the same file serves the test (tests/test_classroom_hub.py):
#   ROS2_COURSE_HOME      the course's clone, read-only for students   (default /opt/ros2-course)
#   ROS2_COURSE_VENV      its venv, built with a Python every user can run (default $ROS2_COURSE_HOME/.venv)
#   ROS2_COURSE_STUDENTS  a file of user names, one a line, who may log in (default /etc/ros2-course/students)
#   ROS2_COURSE_ADMINS    instructors' user names, comma-separated (they may see students' servers)
#   ROS2_COURSE_HUB_STATE the hub's database and cookie secret           (default /srv/ros2-course-hub)
#   ROS2_COURSE_HUB_URL   where the hub listens                          (default http://:8000)
#   ROS2_COURSE_PROXY     the configurable-http-proxy program            (default: found on PATH)
# `c` is the config object JupyterHub passes to this file.
# ruff: noqa: F821

import os
import stat

COURSE_HOME = os.environ.get("ROS2_COURSE_HOME", "/opt/ros2-course")
COURSE_VENV = os.environ.get("ROS2_COURSE_VENV", os.path.join(COURSE_HOME, ".venv"))
PYTHON = os.path.join(COURSE_VENV, "bin", "python")
STUDENTS_FILE = os.environ.get("ROS2_COURSE_STUDENTS", "/etc/ros2-course/students")
HUB_STATE = os.environ.get("ROS2_COURSE_HUB_STATE", "/srv/ros2-course-hub")
WORK_DIR = "~/ros2-course-work"  # each student's working copy (tools/working_copy.py)
KERNEL_IDLE_S = 3600  # an idle kernel is shut down after an hour: its ROS domain is free again


def _not_runnable_by_students(path):
    """The first directory or file on the way to ``path`` (symlinks followed) that other users
    cannot pass or run, or None. A venv made from a Python under /root (pyenv) fails here."""
    real = os.path.realpath(path)
    parts = real.split(os.sep)
    for depth in range(2, len(parts) + 1):
        step = os.sep.join(parts[:depth])
        if not os.stat(step).st_mode & stat.S_IXOTH:
            return step
    return None


if not os.path.exists(PYTHON):
    raise SystemExit(f"No course venv at {COURSE_VENV}: install the course first (docs/classroom.md, "
                     "step 2), or set ROS2_COURSE_HOME / ROS2_COURSE_VENV.")
_blocked = _not_runnable_by_students(PYTHON)
if _blocked:
    raise SystemExit(
        f"Students could not run the course's Python {PYTHON} (it is {os.path.realpath(PYTHON)}): "
        f"{_blocked} is closed to other users. Build the course venv with a system Python "
        "(make setup PYTHON=/usr/bin/python3 in a clone under /opt, docs/classroom.md) instead of "
        "opening up that directory.")

# ---------------------------------------------------------------- the hub
c.JupyterHub.bind_url = os.environ.get("ROS2_COURSE_HUB_URL", "http://:8000")
c.JupyterHub.db_url = f"sqlite:///{os.path.join(HUB_STATE, 'jupyterhub.sqlite')}"
c.JupyterHub.cookie_secret_file = os.path.join(HUB_STATE, "jupyterhub_cookie_secret")
c.JupyterHub.cleanup_servers = True  # stopping the hub stops every student's server
if os.environ.get("ROS2_COURSE_PROXY"):
    c.ConfigurableHTTPProxy.command = [os.environ["ROS2_COURSE_PROXY"]]

# ---------------------------------------------------------------- who may log in
# Students log in with their Unix password (PAM). Create the accounts with useradd (docs/classroom.md).
c.JupyterHub.authenticator_class = "pam"
if os.path.exists(STUDENTS_FILE):
    with open(STUDENTS_FILE, encoding="utf-8") as _names:
        c.Authenticator.allowed_users = {line.strip() for line in _names
                                         if line.strip() and not line.startswith("#")}
c.Authenticator.admin_users = {name.strip() for name in os.environ.get("ROS2_COURSE_ADMINS", "").split(",")
                               if name.strip()}

# ---------------------------------------------------------------- each student's server
c.JupyterHub.spawner_class = "localprocess"  # a process per student, as that Unix user
# Sync the working copy, then become the single-user server (the same process, so the hub's
# stop signals reach the server). classroom/singleuser.py makes the hub's first stop signal
# (SIGINT) shut the kernels down properly, and with them every ROS process they started.
c.Spawner.cmd = [PYTHON, os.path.join(COURSE_HOME, "tools", "working_copy.py"),
                 "--course", os.path.join(COURSE_HOME, "notebooks"), "--work", WORK_DIR,
                 "--then", PYTHON, os.path.join(COURSE_HOME, "classroom", "singleuser.py")]
c.Spawner.notebook_dir = WORK_DIR
c.Spawner.default_url = "/lab/tree/00_welcome.ipynb"
c.Spawner.args = [
    f"--MappingKernelManager.cull_idle_timeout={KERNEL_IDLE_S}",
    "--MappingKernelManager.cull_interval=300",
    "--LabApp.news_url=None",
    "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate",
]
# Nothing of the hub's own environment (its venv's PATH, LD_LIBRARY_PATH, PYTHONPATH) reaches a
# student's server: the course's venv sets its own library path when its Python starts.
c.LocalProcessSpawner.env_keep = ["LANG", "LC_ALL"]
c.Spawner.environment = {
    "PATH": f"{os.path.join(COURSE_VENV, 'bin')}:/usr/local/bin:/usr/bin:/bin",
    "ROS2_COURSE_WORK": WORK_DIR,
    "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",  # the course's default, stated for clarity
    "PYTHONNOUSERSITE": "1",  # packages in ~/.local never shadow the course's pinned stack
}
c.Spawner.start_timeout = 120  # the first start of a server on a loaded host
c.Spawner.http_timeout = 60
