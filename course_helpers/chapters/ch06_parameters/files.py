"""``--params-file`` YAML files: the parameters a file gives one node, and the arguments that load it.

The file maps node names to ``ros__parameters``::

    talker:                 # or /talker, /robot1/talker, /** (every node), /**/talker
      ros__parameters:
        rate_hz: 5.0
        limits:             # nested keys become dotted names: limits.max_speed
          max_speed: 1.5
"""

from __future__ import annotations

import os
import re

from rclpy.parameter import Parameter

from course_helpers.core.errors import CourseError
from course_helpers.core.names import full_name
from course_helpers.core.validation import check_namespace, check_node_name

PARAMS_KEY = "ros__parameters"


def load_parameter_file(path: str, node_name: str, namespace: str = "") -> list[Parameter]:
    """The parameters a ``--params-file`` YAML file gives the node ``namespace/node_name``.

    Entries matching the node are merged in file order, wildcard entries first, so an
    entry naming the node exactly wins.

    Args:
        path: the YAML file (a relative path starts in the current folder).
        node_name: the node's name ('talker').
        namespace: the node's namespace ('' or '/robot1').

    Returns the parameters sorted by name, ready for ``parameter_overrides=``. Raises
    :class:`CourseError` for a missing file, bad YAML, a missing ``ros__parameters`` key
    or a mixed-type list.
    """
    import yaml

    check_node_name(node_name)
    fqn = full_name(check_namespace(namespace), node_name)
    _check_file(path)
    with open(path, encoding="utf-8") as handle:
        try:
            document = yaml.safe_load(handle)
        except yaml.YAMLError as exc:
            raise CourseError(f"{path} is not valid YAML: {exc}") from None
    if not isinstance(document, dict):
        raise CourseError(f"{path} must map node names to '{PARAMS_KEY}:' blocks, "
                          f"got {type(document).__name__}")
    exact, wild = [], []
    for key, values in _node_entries(document, "", path):
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
