"""Stop `make` early, with advice, on a platform the ROS 2 Jazzy wheels do not support."""

import platform
import shutil
import sys

problems = []
if sys.platform != "linux" or platform.machine() not in ("x86_64", "AMD64"):
    problems.append(
        f"this is {sys.platform}/{platform.machine()}; the ROS 2 Jazzy wheels on PyPI are built "
        "for Linux x86_64 only. Elsewhere, use a Linux x86_64 machine, VM or container "
        "(e.g. WSL2 on Windows, a Linux VM on macOS)."
    )
if not (3, 10) <= sys.version_info[:2] <= (3, 13):
    problems.append(
        f"Python {platform.python_version()} found; the wheels need CPython 3.10-3.13. "
        "Run `make PYTHON=python3.12 lab` (or another supported version)."
    )
missing = [tool for tool in ("cmake", "cc", "c++") if shutil.which(tool) is None]
if missing:
    problems.append(
        f"missing build tools: {', '.join(missing)}. The course builds its own ROS interface "
        "package; on Debian/Ubuntu run `sudo apt-get install cmake build-essential`."
    )
if problems:
    print("Cannot set up the course here:", *("  - " + p for p in problems), sep="\n")
    sys.exit(1)
