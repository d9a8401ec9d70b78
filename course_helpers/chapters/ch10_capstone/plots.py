"""The chart of the troubleshooting section: what reaches perception, configuration by configuration."""

from __future__ import annotations

from course_helpers.chapters.ch10_capstone.measure import Delivery


def plot_deliveries(results: dict[str, Delivery]):
    """Bar charts of the delivered rate and the missed frames of each measured configuration.

    Args: ``results`` maps a label to the :class:`.measure.Delivery` measured with it.
    Returns: the matplotlib Figure (end the cell with ``plt.show()``).
    """
    import matplotlib.pyplot as plt

    labels = list(results)
    rates = [results[k].delivered_hz for k in labels]
    missed = [100.0 * results[k].missed_fraction for k in labels]
    expected = max(r.expected_hz for r in results.values())
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.6))
    colours = ["#cf222e" if m > 10 else "#1a7f37" for m in missed]
    left.barh(labels, rates, color=colours)
    left.axvline(expected, color="#333333", linestyle="--", linewidth=1)
    left.text(expected, len(labels) - 0.5, f" camera {expected:g} Hz", va="center", fontsize=8)
    left.set_xlabel("frames processed by perception [Hz]")
    left.set_xlim(0, expected * 1.3)
    left.invert_yaxis()
    right.barh(labels, missed, color=colours)
    right.set_xlabel("frames missed [%]")
    right.set_xlim(0, 100)
    right.invert_yaxis()
    right.set_yticklabels([])
    fig.suptitle("Perception of a 30 Hz camera: what arrives where it is needed")
    fig.tight_layout()
    return fig
