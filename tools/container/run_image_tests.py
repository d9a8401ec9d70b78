"""``make test-image``: build the course's image, test it as students use it, print what it cost.

1. ``make image``'s build (build_image.py): the base image if missing, then the Dockerfile;
2. ``tests/test_image.py`` against that image (pytest, from the host: the checks start containers,
   and Chromium on the host drives the container's JupyterLab);
3. a summary: the image's size, the seconds of the base, of each build stage (system packages,
   pinned stack, ``make setup``) and of the whole build, and each test's seconds. It is written to
   ``build/image/report.json`` too.

Exits non-zero when the build or a test fails. Run it with the course's venv (``make test-image``).

    python -m tools.container.run_image_tests [--tag ros2-course] [--jobs 6] [--no-cache]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

from tools.container.build_image import DEFAULT_TAG, REPO, build_image, summary
from tools.container.engine import EngineError

OUT = REPO / "build" / "image"
TESTS = "tests/test_image.py"


def run_tests(tag: str, jobs: int, junit: Path) -> tuple[int, float]:
    """Run the image's tests against ``tag``; return (pytest's exit status, seconds)."""
    env = dict(os.environ, COURSE_IMAGE=tag, COURSE_IMAGE_JOBS=str(jobs))
    argv = [sys.executable, "-m", "pytest", TESTS, "-v", "-s", "-p", "no:cacheprovider",
            f"--junitxml={junit}"]
    print("$ " + " ".join(argv), flush=True)
    started = time.monotonic()
    status = subprocess.run(argv, cwd=REPO, env=env).returncode
    return status, time.monotonic() - started


def test_seconds(junit: Path) -> list[dict]:
    """Each test's name, outcome and seconds, from pytest's JUnit XML."""
    if not junit.exists():
        return []
    tests = []
    for case in ET.parse(junit).getroot().iter("testcase"):
        outcomes = [child.tag for child in case if child.tag in ("failure", "error", "skipped")]
        tests.append({"test": case.get("name"), "outcome": outcomes[0] if outcomes else "passed",
                      "seconds": round(float(case.get("time", 0)), 1)})
    return tests


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tag", default=DEFAULT_TAG, help=f"the image's name (default {DEFAULT_TAG})")
    parser.add_argument("--jobs", type=int, default=6, help="nbval workers in the container (NB_JOBS)")
    parser.add_argument("--no-cache", action="store_true", help="build every step afresh")
    args = parser.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    try:
        report = build_image(args.tag, args.no_cache, OUT / "build.json")
    except EngineError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    junit = OUT / "tests.xml"
    junit.unlink(missing_ok=True)
    status, seconds = run_tests(args.tag, args.jobs, junit)
    report["test_seconds"] = round(seconds, 1)
    report["tests"] = test_seconds(junit)
    (OUT / "report.json").write_text(json.dumps(report, indent=1) + "\n")
    print("\n" + summary(report))
    for test in report["tests"]:
        print(f"  {test['test']}: {test['outcome']}, {test['seconds']:.0f} s")
    print(f"tests: {seconds:.0f} s in all; build and tests: "
          f"{report['base_seconds'] + report['build_seconds'] + seconds:.0f} s")
    if status != 0:
        print(f"the image's tests failed (pytest exit status {status})", file=sys.stderr)
    elif any(test["outcome"] == "skipped" for test in report["tests"]):
        print("note: some of the image's tests were skipped (reasons above)")
    return status


if __name__ == "__main__":
    sys.exit(main())
