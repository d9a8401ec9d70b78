"""The QoS lab (notebook ``08b_qos_lab``): real experiments with QoS profiles, a widget panel, plots.

* ``config``: :class:`ExperimentConfig`, its limits, ``PRESETS`` and :func:`preset`;
* ``publisher``: :class:`LabPublisher`, the node that runs in a child process;
* ``subscriber``: :class:`LabSubscriber`, the counting node in the kernel;
* ``run``: :func:`run_experiment`, one run from start to clean-up;
* ``link``: the lossy link (both ends in a private network namespace that drops a share of UDP),
  :func:`link_unavailable_reason` where it cannot be made;
* ``results``: :class:`Snapshot` and :class:`ExperimentResult`;
* ``plots``: :func:`draw_results` and the live :class:`ResultsFigure`;
* ``panel``: :func:`qos_lab`, the widget panel; ``table``: its results table;
* ``wire``: a run on the lossy link captured and its repairs read from RTPS (notebook 08c), ``wire_plot``:
  their timeline (imported as modules: ``from course_helpers.chapters.ch08b_lab import wire``).
"""

from __future__ import annotations

from course_helpers.chapters.ch08b_lab.config import (
    MAX_DEPTH,
    MAX_PAYLOAD_BYTES,
    PRESETS,
    TRANSPORTS,
    ExperimentConfig,
    preset,
)
from course_helpers.chapters.ch08b_lab.link import link_unavailable_reason
from course_helpers.chapters.ch08b_lab.publisher import CHILD_LABEL, LabPublisher
from course_helpers.chapters.ch08b_lab.results import ExperimentResult, Snapshot
from course_helpers.chapters.ch08b_lab.run import run_experiment
from course_helpers.chapters.ch08b_lab.subscriber import LabSubscriber

__all__ = ["CHILD_LABEL", "MAX_DEPTH", "MAX_PAYLOAD_BYTES", "PRESETS", "TRANSPORTS", "ExperimentConfig",
           "ExperimentResult", "LabPublisher", "LabSubscriber", "QoSLab", "ResultsFigure", "Snapshot",
           "draw_results", "link_unavailable_reason", "preset", "qos_lab", "run_experiment"]

_LAZY = {"qos_lab": "panel", "QoSLab": "panel", "draw_results": "plots", "ResultsFigure": "plots"}


def __getattr__(name: str):
    # The panel and the plots load ipywidgets and matplotlib (almost a second) on first use, so
    # that the publisher's child process, which imports this package, does not pay for them.
    if name in _LAZY:
        from importlib import import_module

        return getattr(import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
