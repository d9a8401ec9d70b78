"""Which ROS middleware (rmw) implementations are installed (the notebook asks rclpy which one runs)."""

from __future__ import annotations

import os
import sys


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
