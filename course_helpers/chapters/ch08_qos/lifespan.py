"""Lifespan: what a late joiner gets of the messages a transient-local publisher kept.

The notebook writes the talker (``sent_at``) and the late joiner (``received``);
:meth:`LifespanResult.from_nodes` collects what they recorded and :func:`plot_lifespan` draws it.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class LifespanResult:
    """When each numbered message was published, when the late joiner joined, what it got
    (times in seconds since the first message)."""

    lifespan_s: float
    published_at: list[float]
    joined_at: float
    received: list[int]

    def ages_at_join(self) -> list[float]:
        """Each message's age in seconds when the late joiner subscribed."""
        return [self.joined_at - t for t in self.published_at]

    @classmethod
    def from_nodes(cls, talker, joiner, joined_at: float, lifespan_s: float) -> LifespanResult:
        """What ``talker`` (``sent_at``: ``time.monotonic()`` of each message, numbered from 0) and
        ``joiner`` (``received``: message numbers) recorded; ``joined_at`` is the ``time.monotonic()``
        when the joiner subscribed."""
        first = talker.sent_at[0]
        return cls(lifespan_s, [t - first for t in talker.sent_at], joined_at - first,
                   sorted(joiner.received))


def plot_lifespan(result: LifespanResult):
    """A matplotlib figure: each message's age when the late joiner joined, green if delivered."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 2.8))
    ages = result.ages_at_join()
    colours = ["#16a34a" if i in result.received else "#9ca3af" for i in range(len(ages))]
    ax.bar(range(len(ages)), ages, color=colours)
    ax.axhline(result.lifespan_s, color="#dc2626", linestyle="--", label=f"lifespan {result.lifespan_s:g} s")
    ax.set_xlabel("message number (green: delivered to the late joiner, grey: expired)")
    ax.set_ylabel("age at join (s)")
    ax.set_title("Lifespan: stored messages older than the lifespan are dropped", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig
