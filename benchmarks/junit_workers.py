"""A pytest plugin for the soak (``-p benchmarks.junit_workers``): each test's JUnit entry names the
xdist worker that ran it, as the property ``worker``, so that a failure can be read beside the files
that ran before it in the same process (:func:`benchmarks.soak.failures_in`)."""

from __future__ import annotations

import os

WORKER_PROPERTY = "worker"


def pytest_runtest_setup(item):
    # the item's properties go into each of its reports; JUnit writes those of the teardown report
    item.user_properties.append((WORKER_PROPERTY, os.environ.get("PYTEST_XDIST_WORKER", "main")))
