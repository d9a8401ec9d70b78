"""Convert ROS messages to and from YAML, the way ``ros2 topic echo`` and ``ros2 topic pub`` do.

Used by the ``%ros2`` commands (chapters 01-10) and by anything that shows a message
as text or builds one from a YAML string such as ``"{linear: {x: 0.5}}"``.
``rosidl_runtime_py`` is not on PyPI, so this works directly over each message
class's ``get_fields_and_field_types()``.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable

import yaml

from course_helpers.core.errors import CourseError
from course_helpers.core.validation import interface_name

__all__ = ["message_to_dict", "message_to_yaml", "set_message_fields", "values_from_yaml"]


def message_to_dict(msg, truncate_length: int | None = None, no_arr: bool = False,
                    no_str: bool = False) -> dict:
    """A message as plain Python data (dicts in field order, lists, numbers, strings)."""
    out = {}
    for field, type_name in msg.get_fields_and_field_types().items():
        out[field] = plain_value(getattr(msg, field), type_name, truncate_length, no_arr, no_str)
    return out


def plain_value(value, type_name, truncate_length, no_arr, no_str):
    if hasattr(value, "get_fields_and_field_types"):
        return message_to_dict(value, truncate_length, no_arr, no_str)
    if isinstance(value, bytes):
        return value[0] if len(value) == 1 else list(value)
    if isinstance(value, str):
        if no_str:
            return f"<string length: <{len(value)}>>"
        if truncate_length is not None and len(value) > truncate_length:
            return value[:truncate_length] + "..."
        return value
    if hasattr(value, "tolist") or isinstance(value, (list, tuple)):
        items = value.tolist() if hasattr(value, "tolist") else list(value)
        element = element_type(type_name)
        if no_arr:
            kind = "sequence" if type_name.startswith("sequence") else "array"
            return f"<{kind} type: {element}, length: {len(items)}>"
        cut = truncate_length is not None and len(items) > truncate_length
        if cut:
            items = items[:truncate_length]
        items = [plain_value(v, element, truncate_length, no_arr, no_str) for v in items]
        return items + ["..."] if cut else items
    return value


def element_type(type_name: str) -> str:
    if type_name.startswith("sequence<"):
        return type_name[len("sequence<"):].rstrip(">").split(",")[0].strip()
    return type_name.split("[", 1)[0]


def message_to_yaml(msg, truncate_length: int | None = None, no_arr: bool = False,
                    no_str: bool = False, flow_style: bool = False) -> str:
    """A message as YAML text, fields in definition order (what ``ros2 topic echo`` prints)."""
    return _dump_yaml(message_to_dict(msg, truncate_length, no_arr, no_str), flow_style)


def _dump_yaml(data, flow_style: bool = False) -> str:
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=sys.maxsize,
                          default_flow_style=flow_style)


def message_to_csv(msg, truncate_length, no_arr, no_str) -> str:
    def flatten(value):
        if isinstance(value, dict):
            return [item for v in value.values() for item in flatten(v)]
        if isinstance(value, list):
            return [item for v in value for item in flatten(v)]
        return [str(value)]

    return ",".join(flatten(message_to_dict(msg, truncate_length, no_arr, no_str)))


def values_from_yaml(text: str, what: str = "message") -> dict:
    """Parse the YAML dictionary of a ``pub``/``call``/``send_goal`` command."""
    try:
        values = yaml.safe_load(text) if text.strip() else {}
    except yaml.YAMLError as exc:
        raise CourseError(f"the {what} values are not valid YAML ({exc.__class__.__name__}): {text!r}. "
                          "Write a dictionary such as \"{linear: {x: 0.5}, angular: {z: 0.1}}\".") from None
    if values is None:
        values = {}
    if not isinstance(values, dict):
        raise CourseError(f"the {what} values must be a YAML dictionary, got {text!r}. "
                          "Write field: value pairs such as \"{data: hello}\".")
    return values


def set_message_fields(msg, values: dict, now: Callable | None = None, _path: str = ""):
    """Fill ``msg`` from a dict (nested dicts for nested messages, lists for arrays); return it.

    Numbers and strings are converted to the field's type; ``now`` (a function
    returning a builtin_interfaces/msg/Time) lets a Time field take the value 'now'.
    Raises :class:`CourseError` naming the field and what it accepts.
    """
    if not isinstance(values, dict):
        raise CourseError(f"{_path.rstrip('.') or 'the message'} ({interface_name(type(msg))}) needs a "
                          f"dictionary of its fields, got {values!r}")
    fields = msg.get_fields_and_field_types()
    slot_types = dict(zip(fields, msg.SLOT_TYPES, strict=True))
    for key, value in values.items():
        path = f"{_path}{key}"
        if key not in fields:
            raise CourseError(f"{interface_name(type(msg))} has no field {path!r}; its fields are: "
                              f"{', '.join(fields) or '(none)'}")
        converted = _convert_field(getattr(msg, key), slot_types[key], fields[key], value, path, now)
        try:
            setattr(msg, key, converted)
        except (AssertionError, TypeError, ValueError, OverflowError) as exc:
            raise CourseError(f"cannot set field {path!r} ({fields[key]}) to {value!r}: {exc}") from None
    return msg


def _convert_field(current, slot_type, type_name, value, path, now):
    from rosidl_parser import definition as idl

    if isinstance(slot_type, idl.NamespacedType):
        cls = type(current)
        if isinstance(value, cls):
            return value
        is_time = interface_name(cls) == "builtin_interfaces/msg/Time"
        if is_time and now is not None and value in ("now", "auto"):
            return now()
        return set_message_fields(cls(), value, now, path + ".")
    if isinstance(slot_type, idl.AbstractNestedType):
        if not isinstance(value, (list, tuple)):
            raise CourseError(f"field {path!r} ({type_name}) needs a list such as [1, 2, 3], got {value!r}")
        if isinstance(slot_type, idl.Array) and len(value) != slot_type.size:
            raise CourseError(f"field {path!r} ({type_name}) needs exactly {slot_type.size} items, "
                              f"got {len(value)}")
        element = slot_type.value_type
        if isinstance(element, idl.NamespacedType):
            cls = getattr(importlib.import_module(".".join(element.namespaces)), element.name)
            return [item if isinstance(item, cls) else set_message_fields(cls(), item, now, f"{path}[{i}].")
                    for i, item in enumerate(value)]
        return [_convert_primitive(element, item, f"{path}[{i}]") for i, item in enumerate(value)]
    return _convert_primitive(slot_type, value, path)


def _convert_primitive(slot_type, value, path):
    from rosidl_parser import definition as idl

    if isinstance(slot_type, (idl.AbstractString, idl.AbstractWString)):
        if isinstance(value, (dict, list)):
            raise CourseError(f"field {path!r} (string) needs text, got {value!r}; quote text that "
                              "contains ':', '{' or '[' (e.g. \"{data: 'a: b'}\")")
        return value if isinstance(value, str) else str(value)
    kind = getattr(slot_type, "typename", "")
    try:
        if kind == "boolean":
            if isinstance(value, bool):
                return value
            if isinstance(value, str) and value.lower() in ("true", "false"):
                return value.lower() == "true"
            if value in (0, 1):
                return bool(value)
            raise ValueError
        if kind in ("float", "double", "long double"):
            if isinstance(value, bool):
                raise ValueError
            return float(value)
        if kind == "octet":
            if isinstance(value, bytes):
                return value
            return bytes([int(value)])
        if kind == "char" and isinstance(value, str):
            return value
        if isinstance(value, bool):
            raise ValueError
        if isinstance(value, float):
            if not value.is_integer():
                raise ValueError
            return int(value)
        return int(value)
    except (TypeError, ValueError, OverflowError):
        wanted = {"boolean": "true or false", "octet": "a byte 0-255"}.get(
            kind, "a number" if kind in ("float", "double") else "a whole number")
        raise CourseError(f"field {path!r} ({kind or slot_type}) needs {wanted}, got {value!r}") from None
