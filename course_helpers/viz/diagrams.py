"""Explanatory pictures shared by the chapters (chapter 00: how a notebook runs ROS).

Measured plots live next to the code that measures them (``timing.py``,
``lab_plots.py``, ...); this module draws the diagrams that explain the course's
own machinery.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch


def _box(ax, x, y, w, h, text, colour):
    ax.add_patch(FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0.02,rounding_size=0.03",
                                facecolor=colour, edgecolor="#333333", linewidth=1.2))
    ax.text(x + w / 2, y + h / 2, text, ha="center", va="center", fontsize=9, wrap=True)


def _arrow(ax, start, end, text="", both=False):
    ax.add_patch(FancyArrowPatch(start, end, arrowstyle="<->" if both else "->",
                                 mutation_scale=12, linewidth=1.2, color="#333333"))
    if text:
        ax.text((start[0] + end[0]) / 2, (start[1] + end[1]) / 2 + 0.03, text, ha="center",
                fontsize=8, color="#333333")


def draw_runtime_diagram():
    """Draw the kernel: cells on the main thread, nodes on the executor thread, child processes.

    Returns the matplotlib Figure (chapter 00).
    """
    fig, ax = plt.subplots(figsize=(9, 4.2))
    ax.set_xlim(0, 1.5)
    ax.set_ylim(0, 1)
    ax.axis("off")
    ax.add_patch(FancyBboxPatch((0.02, 0.05), 0.98, 0.88, boxstyle="round,pad=0.01",
                                facecolor="#f6f8fa", edgecolor="#888888", linestyle="--"))
    ax.text(0.04, 0.88, "Jupyter kernel process (one ROS domain, localhost discovery)",
            fontsize=9, style="italic")
    _box(ax, 0.06, 0.52, 0.36, 0.28, "main thread\nruns your cells\n(stop button interrupts it)",
         "#dbeafe")
    _box(ax, 0.56, 0.52, 0.40, 0.28, "executor thread\nspins every node you rt.add()\n"
         "(timers, subscriptions, services)", "#dcfce7")
    _box(ax, 0.06, 0.12, 0.36, 0.26, "rt = get_runtime()\nits own rclpy Context,\nsignal handlers off",
         "#fef9c3")
    _box(ax, 0.56, 0.12, 0.40, 0.26, "node consoles\nprints and logs of callbacks\nshown under their cell",
         "#fce7f3")
    _box(ax, 1.12, 0.40, 0.34, 0.34, "child processes\nrt.spawn(...)\nnodes over real\nSHM / UDP transport",
         "#ede9fe")
    _arrow(ax, (0.42, 0.66), (0.56, 0.66), "add / wait")
    _arrow(ax, (0.24, 0.38), (0.24, 0.52))
    _arrow(ax, (0.76, 0.52), (0.76, 0.38))
    _arrow(ax, (0.96, 0.62), (1.12, 0.58), "DDS", both=True)
    ax.set_title("How a course notebook runs ROS 2", fontsize=11)
    fig.tight_layout()
    return fig
