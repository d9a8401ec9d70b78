# The course in one container image, for every route that is not a Linux x86_64 machine of your own:
#   * Dev Containers and GitHub Codespaces build it (.devcontainer/devcontainer.json);
#   * Binder builds it (repo2docker uses the Dockerfile at the root when there is no binder/ folder);
#   * Zero to JupyterHub runs it as each student's single-user image (classroom/values.yaml);
#   * plain Docker or Podman run it (the README's "No Linux machine?").
# Its steps are the README's set-up: Debian's system packages, then `make setup` with the system
# Python (Debian 12: 3.11). The course lands in /opt/ros2-course, owned by root and read-only for
# the student: jovyan, uid 1000, as Binder and the chart run it. The student's work lives in their
# home, in ~/ros2-course-work, which may be a volume; at every start the entrypoint brings it up to
# date with the course without overwriting their edits (tools/working_copy.py, as `make lab` does).
#
#     make image                      # with Docker or Podman; `make test-image` builds and tests it
#     docker build -t ros2-course .   # the same by hand (add --platform linux/amd64 on an ARM machine)
FROM debian:bookworm-slim

# The README's system packages (compiler, CMake, venv) and make; tini, the container's init, reaps
# kernels' children. For later chapters: Debian's ROS 1 (rospy, the master, rosnode, rostopic), the
# network tools ip and nft, and Wireshark's tshark and dumpcap (RTPS on the wire, 07b and 08c; the
# student runs dumpcap inside a user namespace of the course, so it needs no setuid bit).
RUN echo "wireshark-common wireshark-common/install-setuid boolean false" | debconf-set-selections \
 && apt-get update \
 && DEBIAN_FRONTEND=noninteractive apt-get install --yes --no-install-recommends \
      build-essential cmake make python3-venv python3-dev ca-certificates tini \
      python3-rospy python3-rosmaster python3-std-msgs python3-rosnode python3-rostopic \
      iproute2 nftables tshark \
 && rm -rf /var/lib/apt/lists/*

# The student, as in jupyter/docker-stacks: jovyan, uid 1000, group users (100).
RUN useradd --create-home --uid 1000 --gid users --shell /bin/bash jovyan

# The pinned stack first, as `make setup` installs it but from environment.txt alone, so that a
# change to the course's own files does not download it again (`make setup` below finds it there).
# A cache layer only: `make setup` stays the one recipe.
COPY environment.txt /opt/ros2-course/environment.txt
RUN python3 -m venv /opt/ros2-course/.venv \
 && /opt/ros2-course/.venv/bin/pip install --quiet --no-cache-dir --upgrade pip \
 && /opt/ros2-course/.venv/bin/pip install --quiet --no-cache-dir -r /opt/ros2-course/environment.txt

# The course, installed by its own set-up (.dockerignore keeps a local .venv and build output out).
COPY . /opt/ros2-course
WORKDIR /opt/ros2-course
RUN make setup PYTHON=/usr/bin/python3 \
 && .venv/bin/python -c "import jupyterhub, jupyterlab, rclpy, course_interfaces" \
 && rm -rf build log /root/.cache

# JUPYTER_CONFIG_PATH: the student configuration of `make lab` (tools/lab.py), which hides
# nbgrader's instructor UI; a classroom's instructor image or an instructor's `docker run -e` changes it.
ENV PATH=/opt/ros2-course/.venv/bin:$PATH \
    JUPYTER_CONFIG_PATH=/opt/ros2-course/tools/jupyterlab/student \
    ROS2_COURSE_WORK=/home/jovyan/ros2-course-work \
    PYTHONNOUSERSITE=1 \
    JUPYTER_PORT=8888

# The working copy, made now so that the home holds the notebooks before anything runs.
USER 1000
WORKDIR /home/jovyan
RUN python /opt/ros2-course/tools/working_copy.py

EXPOSE 8888
# Bring the working copy up to date, then run the command: JupyterLab by default; BinderHub and
# Zero to JupyterHub give `jupyterhub-singleuser` instead, which runs the same way.
ENTRYPOINT ["tini", "-g", "--", "/opt/ros2-course/tools/container/start-course"]
CMD ["jupyter", "lab", "--ip=0.0.0.0", "--no-browser", "--notebook-dir=/home/jovyan/ros2-course-work"]
