"""Parameter helpers for chapter 06: YAML parameter files, a rate-retuning slider, a launch equivalent.

* :func:`load_parameter_file` reads a ``ros2 --params-file`` YAML file and returns
  the parameters of one node, ready for ``parameter_overrides=``.
* :class:`RateTuner` sets a running node's ``rate_hz`` through its parameter
  services (as ``ros2 param set`` does), measures the rate its topic really has,
  plots both, and offers a slider widget that does the same live.
* :func:`launch` starts several nodes together, each in its own child process
  with its own parameters, the way a launch file does; :class:`LaunchGroup`
  stops them together. ``launch`` (the ROS package) is not on PyPI.
* :class:`RateTalker` and :class:`CountingListener` are the configurable nodes
  those child processes run.
"""

from __future__ import annotations

import io
import math
import os
import re
import threading
import time
from collections import deque
from dataclasses import dataclass, field

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python
from std_msgs.msg import String

from course_helpers.core.errors import CourseError, WaitTimeout
from course_helpers.core.validation import (
    check_namespace,
    check_node_name,
    check_topic_name,
    resolve_interface,
)

PARAMS_KEY = "ros__parameters"


# ---------------------------------------------------------------------- YAML parameter files
def load_parameter_file(path: str, node_name: str, namespace: str = "") -> list[Parameter]:
    """Return the parameters a ``--params-file`` YAML file gives the node ``namespace/node_name``.

    The file maps node names to ``ros__parameters``::

        talker:                 # or /talker, /robot1/talker, /** (every node), /**/talker
          ros__parameters:
            rate_hz: 5.0
            limits:             # nested keys become dotted names: limits.max_speed
              max_speed: 1.5

    Entries matching the node are merged in file order, wildcard entries first, so
    an entry naming the node exactly wins. Raises :class:`CourseError` for a
    missing file, bad YAML, a missing ``ros__parameters`` key or a mixed-type list.
    """
    import yaml

    check_node_name(node_name)
    fqn = check_namespace(namespace).rstrip("/") + "/" + node_name
    _check_file(path)
    with open(path, encoding="utf-8") as handle:
        try:
            document = yaml.safe_load(handle)
        except yaml.YAMLError as exc:
            raise CourseError(f"{path} is not valid YAML: {exc}") from None
    if not isinstance(document, dict):
        raise CourseError(f"{path} must map node names to '{PARAMS_KEY}:' blocks, "
                          f"got {type(document).__name__}")
    entries = list(_node_entries(document, "", path))
    exact, wild = [], []
    for key, values in entries:
        if key == fqn:
            exact.append(values)
        elif _wildcard_matches(key, fqn):
            wild.append(values)
    merged: dict[str, object] = {}
    for values in wild + exact:
        merged.update(values)
    return [_to_parameter(name, value, path) for name, value in sorted(merged.items())]


def params_file_arguments(path: str) -> list[str]:
    """``['--ros-args', '--params-file', path]`` for ``Node(..., cli_args=...)``, after checking the file."""
    _check_file(path)
    return ["--ros-args", "--params-file", os.fspath(path)]


def _check_file(path) -> None:
    if not isinstance(path, (str, os.PathLike)) or not os.path.isfile(path):
        raise CourseError(f"parameter file {path!r} not found (a relative path starts in the current "
                          "folder, which is the notebook's own folder in a notebook)")


def _node_entries(mapping: dict, prefix: str, path: str):
    """Yield (node key, flat parameter dict) per ``ros__parameters`` block, nested namespaces included."""
    for key, value in mapping.items():
        if not isinstance(key, str) or not isinstance(value, dict):
            raise CourseError(f"{path}: under {prefix or 'the top level'!r}, {key!r} must be a node name "
                              f"followed by a mapping with '{PARAMS_KEY}:'")
        name = key if key.startswith("/") else "/" + key
        name = (prefix.rstrip("/") + name) if prefix else name
        if PARAMS_KEY in value:
            params = value[PARAMS_KEY]
            if not isinstance(params, dict):
                raise CourseError(f"{path}: '{key}: {PARAMS_KEY}:' must be a mapping of name: value")
            yield name, dict(_flatten(params, ""))
            others = {k: v for k, v in value.items() if k != PARAMS_KEY}
            if others:
                raise CourseError(f"{path}: {key!r} has keys besides '{PARAMS_KEY}': {sorted(others)}")
        else:
            yield from _node_entries(value, name, path)


def _flatten(params: dict, prefix: str):
    for key, value in params.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            yield from _flatten(value, name + ".")
        else:
            yield name, value


def _wildcard_matches(pattern: str, fqn: str) -> bool:
    if "*" not in pattern:
        return False
    regex = ""
    for token in re.split(r"(\*\*|\*)", pattern):
        if token == "**":
            regex += ".*"
        elif token == "*":
            regex += "[^/]*"
        else:
            regex += re.escape(token)
    regex = regex.replace("/.*/", "(/.*)?/")  # '/**/talker' also matches '/talker'
    return re.fullmatch(regex, fqn) is not None


def _to_parameter(name: str, value, path: str) -> Parameter:
    if isinstance(value, list):
        if not value:
            raise CourseError(f"{path}: parameter {name!r} is an empty list; ROS cannot tell its type")
        kinds = {bool if isinstance(v, bool) else type(v) for v in value}
        if len(kinds) != 1 or kinds.pop() not in (bool, int, float, str):
            raise CourseError(f"{path}: parameter {name!r} = {value!r} mixes types; a ROS array holds "
                              "only booleans, only integers, only floats (write 1.0, not 1) or only strings")
    elif value is None or not isinstance(value, (bool, int, float, str)):
        raise CourseError(f"{path}: parameter {name!r} has value {value!r}; allowed are booleans, "
                          "integers, floats, strings and lists of one of those")
    return Parameter(name, value=value)


# ---------------------------------------------------------------------- configurable nodes (child targets)
def _range_descriptor(description: str, low: float, high: float) -> ParameterDescriptor:
    return ParameterDescriptor(description=description, floating_point_range=[
        FloatingPointRange(from_value=low, to_value=high, step=0.0)])


class RateTalker(Node):
    """Publishes '<message> N' on ``topic`` at ``rate_hz``; rate and message can change while it runs."""

    def __init__(self, name: str = "talker", **node_kwargs):
        super().__init__(name, **node_kwargs)
        self.declare_parameter("topic", "chatter", ParameterDescriptor(
            description="topic to publish on (fixed at start)", read_only=True))
        self.declare_parameter("rate_hz", 2.0, _range_descriptor("publish rate [Hz]", 0.5, 50.0))
        self.declare_parameter("message", "hello", ParameterDescriptor(description="text before the count"))
        self.count = 0
        self.publisher = self.create_publisher(String, self.get_parameter("topic").value, 10)
        self.timer = self.create_timer(1.0 / self.get_parameter("rate_hz").value, self.tick)
        self.add_post_set_parameters_callback(self.on_parameters_set)

    def on_parameters_set(self, parameters: list[Parameter]) -> None:
        for parameter in parameters:
            if parameter.name == "rate_hz":
                self.timer.timer_period_ns = int(1e9 / parameter.value)  # period [ns]

    def tick(self) -> None:
        self.publisher.publish(String(data=f"{self.get_parameter('message').value} {self.count}"))
        self.count += 1


class CountingListener(Node):
    """Subscribes to ``topic`` and logs a line every ``log_every`` messages."""

    def __init__(self, name: str = "listener", **node_kwargs):
        super().__init__(name, **node_kwargs)
        self.declare_parameter("topic", "chatter", ParameterDescriptor(
            description="topic to listen to (fixed at start)", read_only=True))
        self.declare_parameter("log_every", 10, ParameterDescriptor(
            description="log one line per this many messages",
            integer_range=[IntegerRange(from_value=1, to_value=1000, step=1)]))
        self.heard = 0
        self.subscription = self.create_subscription(String, self.get_parameter("topic").value,
                                                     self.on_message, 10)

    def on_message(self, msg: String) -> None:
        self.heard += 1
        if self.heard % self.get_parameter("log_every").value == 0:
            self.get_logger().info(f"heard {self.heard} messages, last: {msg.data}")


NODE_KINDS = {"talker": RateTalker, "listener": CountingListener}


def make_configured_node(kind: str, name: str, namespace: str = "", parameters: dict | None = None,
                         params_file: str | None = None) -> Node:
    """Child-process target: a :data:`NODE_KINDS` node with a parameter file and/or parameter values.

    Like a launch file's ``Node(parameters=[file, {...}])``, values given in
    ``parameters`` override those from ``params_file``.
    """
    if kind not in NODE_KINDS:
        raise CourseError(f"kind must be one of {', '.join(sorted(NODE_KINDS))}, got {kind!r}")
    overrides = [Parameter(key, value=value) for key, value in (parameters or {}).items()]
    cli_args = params_file_arguments(params_file) if params_file else None
    return NODE_KINDS[kind](name, namespace=namespace, parameter_overrides=overrides, cli_args=cli_args)


# ---------------------------------------------------------------------- launch equivalent
@dataclass
class NodeLaunch:
    """One node of a launch description: what :func:`launch` starts in a child process."""

    kind: str  # 'talker' or 'listener'
    name: str
    namespace: str = ""
    parameters: dict = field(default_factory=dict)
    params_file: str | None = None

    @property
    def fqn(self) -> str:
        return check_namespace(self.namespace).rstrip("/") + "/" + self.name


class LaunchGroup:
    """Nodes started together by :func:`launch`; ``stop()`` ends them together (Ctrl+C on ros2 launch)."""

    def __init__(self, rt, label: str, entries: list[tuple[str, NodeLaunch]]):
        self.rt = rt
        self.label = label
        self.entries = entries

    @property
    def node_names(self) -> list[str]:
        """Full names of the group's nodes, sorted."""
        return sorted(entry.fqn for _, entry in self.entries)

    @property
    def alive(self) -> bool:
        """True while every child process of the group runs."""
        children = self.rt.children()
        return all(child in children and children[child].alive for child, _ in self.entries)

    def stop(self) -> dict[str, int | None]:
        """Stop every child (SIGTERM, then SIGKILL); return exit codes by node name."""
        codes = self.rt.stop_children([child for child, _ in self.entries])
        return {entry.fqn: codes.get(child) for child, entry in self.entries}

    def __repr__(self) -> str:
        state = "running" if self.alive else "stopped"
        return f"<LaunchGroup {self.label!r}: {', '.join(self.node_names)} ({state})>"


def launch(nodes: list[NodeLaunch], label: str = "launch", rt=None, timeout_s: float = 20.0) -> LaunchGroup:
    """Start every node of ``nodes`` in its own child process, then wait until all are in the graph.

    Re-running with the same ``label`` stops the previous group's processes first.
    """
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    check_node_name(label)
    if not nodes or not all(isinstance(n, NodeLaunch) for n in nodes):
        raise CourseError("launch() takes a non-empty list of NodeLaunch(kind, name, namespace, parameters)")
    names = [n.fqn for n in nodes]
    if len(set(names)) != len(names):
        raise CourseError(f"two nodes would share a name: {sorted(names)}; give each a name or namespace")
    for stale in [c for c in rt.children() if c.startswith(label + "__")]:
        rt.stop_child(stale)
    entries = []
    for node in nodes:
        if node.kind not in NODE_KINDS:
            raise CourseError(f"kind must be one of {', '.join(sorted(NODE_KINDS))}, got {node.kind!r}")
        check_node_name(node.name)
        params_file = os.path.abspath(node.params_file) if node.params_file else None
        if params_file:
            params_file_arguments(params_file)
        child = f"{label}__{node.fqn.strip('/').replace('/', '_')}"
        rt.spawn(child, "course_helpers.chapters.ch06_parameters:make_configured_node",
                 params={"kind": node.kind, "name": node.name, "namespace": node.namespace,
                         "parameters": node.parameters, "params_file": params_file})
        entries.append((child, node))
    group = LaunchGroup(rt, label, entries)
    try:
        rt.wait_until(lambda: set(names) <= set(rt.graph_nodes()) or not group.alive, timeout_s,
                      f"the launched nodes {', '.join(sorted(names))}")
    except WaitTimeout:
        group.stop()
        raise
    if not group.alive:
        logs = "\n".join(rt.children()[c].log()[-800:] for c, _ in entries if c in rt.children())
        group.stop()
        raise CourseError(f"a launched node exited during start-up. Output:\n{logs}")
    return group


# ---------------------------------------------------------------------- retuning a running node
class RateTuner:
    """Retune a running node's publish rate through its parameter services and measure the result.

    ``RateTuner('/talker', 'chatter')`` adds a helper node ``rate_tuner`` (re-running
    replaces it) that subscribes to the topic and talks to ``/talker``'s parameter
    services like ``ros2 param set`` does. :meth:`set_rate` changes ``rate_hz``,
    :meth:`measure` counts what really arrives, :meth:`plot` draws requested vs
    measured rate over time, and :meth:`widget` is a slider that does it live.
    """

    def __init__(self, target: str, topic: str, msg_type="std_msgs/msg/String", parameter: str = "rate_hz",
                 minimum: float = 0.5, maximum: float = 20.0, rt=None):
        from rclpy.parameter_client import AsyncParameterClient

        from course_helpers.core.runtime import get_runtime

        self.rt = rt or get_runtime()
        self.target = target if target.startswith("/") else "/" + target
        check_topic_name(topic)
        self.topic = topic
        self.parameter = parameter
        self.minimum, self.maximum = float(minimum), float(maximum)
        self.started = time.monotonic()
        self.arrivals: deque[float] = deque(maxlen=5000)
        self.setpoints: list[tuple[float, float]] = []  # (seconds since start, requested Hz)
        self.samples: list[tuple[float, float]] = []  # rolling rate: (seconds since start, Hz)
        self.measurements: list[tuple[float, float]] = []  # measure() results: (seconds since start, Hz)
        self._widgets = None
        self._ticks = 0
        self._note = ("", 0.0)  # (HTML message, shown until this time)
        self._lock = threading.Lock()
        self.node = self.rt.add(Node, "rate_tuner", console=False)
        self.client = AsyncParameterClient(self.node, self.target)
        self.node.create_subscription(resolve_interface(msg_type, "msg"), topic, self._on_message, 10)
        self.node.create_timer(0.5, self._tick)  # rolling measurement and live refresh [s]
        if not self.client.wait_for_services(5.0):
            raise CourseError(f"node {self.target} has no parameter services; is it running? "
                              f"`%ros2 node list` shows the nodes there are")
        current = self.get_rate()
        self.setpoints.append((0.0, current))

    # ------------------------------------------------------------------ parameter access
    def get_rate(self) -> float:
        """The target's current ``rate_hz``, read through its get_parameters service."""
        response = self.rt.wait_for_future(self.client.get_parameters([self.parameter]), 3.0,
                                           f"{self.target}'s {self.parameter}")
        if not response.values or response.values[0].type == 0:
            raise CourseError(f"{self.target} has no parameter {self.parameter!r}")
        return parameter_value_to_python(response.values[0])

    def set_rate(self, hz: float):
        """Ask the target to use ``hz``; returns the SetParametersResult (``successful``, ``reason``)."""
        if isinstance(hz, bool) or not isinstance(hz, (int, float)) or not math.isfinite(hz):
            raise CourseError(f"rate must be a number of Hz, got {hz!r}")
        request = [Parameter(self.parameter, value=float(hz))]
        response = self.rt.wait_for_future(self.client.set_parameters(request), 3.0,
                                           f"{self.target} to set {self.parameter}")
        result = response.results[0]
        if result.successful:
            with self._lock:
                self.setpoints.append((self._now(), float(hz)))
        return result

    # ------------------------------------------------------------------ measuring
    def measure(self, seconds: float = 1.5, settle_s: float = 0.3) -> float:
        """Wait ``settle_s``, then return the rate [Hz] of messages that arrive during ``seconds``."""
        time.sleep(settle_s)
        start = time.monotonic()
        time.sleep(seconds)
        end = time.monotonic()
        rate = self._rate_between(start, end)
        with self._lock:
            self.measurements.append(((start + end) / 2 - self.started, rate))
        return rate

    def rolling_rate(self, window_s: float = 1.0) -> float:
        """The rate [Hz] of the messages of the last ``window_s`` seconds."""
        now = time.monotonic()
        return self._rate_between(now - window_s, now)

    def _rate_between(self, start: float, end: float) -> float:
        """Messages per second between two monotonic times, from the spacing of the arrivals."""
        with self._lock:
            window = [t for t in self.arrivals if start <= t <= end]
        if len(window) >= 3:
            return (len(window) - 1) / (window[-1] - window[0])
        return len(window) / (end - start)

    def _on_message(self, _msg) -> None:
        with self._lock:
            self.arrivals.append(time.monotonic())

    def _now(self) -> float:
        return time.monotonic() - self.started

    def _tick(self) -> None:
        self._ticks += 1
        if self._now() >= 1.0:
            rate = self.rolling_rate()
            with self._lock:
                self.samples.append((self._now() - 0.5, rate))
                del self.samples[:-600]
        if self._widgets is not None and self._ticks % 2 == 0:  # redraw once a second
            self._refresh_widgets()

    # ------------------------------------------------------------------ pictures and widgets
    def draw(self, ax) -> None:
        """Draw requested (steps) and measured (dots) rate over time on a matplotlib Axes."""
        with self._lock:
            setpoints = list(self.setpoints)
            samples = sorted(self.samples)
            measurements = list(self.measurements)
        end = max([self._now()] + [t for t, _ in samples])
        xs = [t for t, _ in setpoints] + [end]
        ys = [hz for _, hz in setpoints] + [setpoints[-1][1]]
        ax.step(xs, ys, where="post", color="#2563eb", linewidth=2, label=f"requested {self.parameter}")
        if samples:
            ax.plot([t for t, _ in samples], [hz for _, hz in samples], "-", color="#f97316",
                    linewidth=1, alpha=0.8, label=f"measured on {self.topic} (1 s window)")
        if measurements:
            ax.plot([t for t, _ in measurements], [hz for _, hz in measurements], "D", color="#c2410c",
                    markersize=7, label="measure() result")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("rate [Hz]")
        top = max(ys + [hz for _, hz in samples + measurements] + [1.0])
        ax.set_ylim(0, top * 1.25)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", fontsize=8)
        ax.set_title(f"{self.target}: requested vs measured publish rate", fontsize=10)

    def plot(self):
        """A matplotlib Figure of requested vs measured rate (pyplot, for a notebook cell)."""
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7.5, 3.2))
        self.draw(ax)
        fig.tight_layout()
        return fig

    def widget(self):
        """A slider that sets the rate live, a measured-rate label and a plot refreshed twice a second."""
        import ipywidgets as widgets

        current = self.setpoints[-1][1]
        slider = widgets.FloatSlider(value=current, min=self.minimum, max=self.maximum, step=0.5,
                                     description=f"{self.parameter}", continuous_update=False)
        label = widgets.HTML()
        image = widgets.Image(format="png")
        slider.observe(lambda change: self._on_slider(change["new"], label), names="value")
        self._widgets = (slider, label, image)
        self._refresh_widgets()
        return widgets.VBox([widgets.HBox([slider, label]), image])

    def _on_slider(self, hz: float, label) -> None:
        try:
            result = self.set_rate(hz)
            problem = "" if result.successful else f"rejected: {result.reason}"
        except (CourseError, TimeoutError) as error:
            problem = str(error)
        if problem:
            self._note = (f"<span style='color:#cf222e'>{problem}</span>", time.monotonic() + 4.0)
            label.value = self._note[0]

    def _refresh_widgets(self) -> None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        _slider, label, image = self._widgets
        note, until = self._note
        label.value = note if time.monotonic() < until else f"measured: <b>{self.rolling_rate():.1f} Hz</b>"
        fig = Figure(figsize=(7.5, 3.0), dpi=80)
        FigureCanvasAgg(fig)
        self.draw(fig.add_subplot())
        fig.tight_layout()
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png")
        image.value = buffer.getvalue()

