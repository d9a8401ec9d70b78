"""Which ROS middleware (rmw) implementation runs, and which ones are installed."""

from __future__ import annotations

import os
import sys

from course_helpers.core.versions import package_version


def installed_rmw_implementations(prefix: str = sys.prefix) -> list[str]:
    """Names of the rmw implementations whose libraries are in ``prefix``/lib, sorted."""
    lib = os.path.join(prefix, "lib")
    found = set()
    for name in os.listdir(lib) if os.path.isdir(lib) else []:
        if name.startswith("librmw_") and name.endswith(".so"):
            impl = name[len("lib"):-len(".so")]
            if not impl.endswith(("_shared_cpp", "_common")) and "dds_common" not in impl \
                    and impl not in ("rmw_implementation",):
                found.add(impl)
    return sorted(found)


def middleware_report() -> dict:
    """A dict: the active rmw implementation, what RMW_IMPLEMENTATION says, the installed ones,
    and the Fast DDS version."""
    import rclpy

    return {
        "active": rclpy.get_rmw_implementation_identifier(),
        "RMW_IMPLEMENTATION": os.environ.get("RMW_IMPLEMENTATION", "(not set: the default is used)"),
        "installed": installed_rmw_implementations(),
        "Fast DDS": package_version("ros-fastrtps"),
    }
