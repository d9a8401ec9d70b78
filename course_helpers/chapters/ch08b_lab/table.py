"""The QoS lab's results table: one HTML row per run, with a note on how each run ended.

``results_table_html(results)`` is what the panel shows under its plot and what its static record
keeps, so a saved notebook shows the same table.
"""

from __future__ import annotations

import html

from course_helpers.chapters.ch08b_lab.results import ExperimentResult

_ROW_COLUMNS = (("#", None), ("run", "run"), ("sent", "published"), ("delivered", "delivered"),
                ("lost (gaps)", "lost_seq"), ("lost (events)", "lost_events"), ("in flight", "in_flight"),
                ("publish errors", "publish_errors"), ("p50 ms", "p50_ms"), ("p99 ms", "p99_ms"),
                ("loopback MB", "loopback_mb"), ("note", "note"))

# What a column's header means, shown as its tooltip and, for the one a reader meets first without its
# explanation, in a line under the table.
LOOPBACK_NOTE = ("loopback MB: the megabytes received on this machine's loopback interface (lo) during the "
                 "run, by every process: samples sent over UDP cross it, samples sent through shared memory "
                 "do not (what remains is discovery and other programs' traffic)")
_TIPS = {"loopback_mb": LOOPBACK_NOTE, "lost_seq": "samples missing from the sequence numbers received",
         "lost_events": "the subscription's message_lost events", "in_flight": "sent, not yet seen when the "
         "run ended: not lost"}

_TH = ('style="padding:2px 6px;border-bottom:1px solid #999;text-align:{align};vertical-align:bottom;'
       'white-space:nowrap"')
_TD = 'style="padding:2px 6px;border-bottom:1px solid #ddd;text-align:{align}"'


def results_table_html(results: list[ExperimentResult]) -> str:
    """The results table as HTML: one row per run, oldest first."""
    def align(key):
        return "left" if key in ("run", "note") else "right"

    head = "".join(f"<th {_TH.format(align=align(key))}"
                   + (f' title="{html.escape(_TIPS[key])}"' if key in _TIPS else "")
                   + f">{html.escape(name)}</th>" for name, key in _ROW_COLUMNS)
    rows = []
    for number, result in enumerate(results, 1):
        row = result.as_row()
        row["note"] = _note(result)
        cells = [(str(number), None)] + [(_cell(row.get(key)), key) for _name, key in _ROW_COLUMNS[1:]]
        rows.append("<tr>" + "".join(f"<td {_TD.format(align=align(key))}>{html.escape(text)}</td>"
                                     for text, key in cells) + "</tr>")
    if not rows:
        rows.append(f'<tr><td colspan="{len(_ROW_COLUMNS)}" style="padding:4px 6px"><i>no runs yet: each '
                    "run adds a row here</i></td></tr>")
    return ('<table class="qos-lab-results" style="font-size:12px;border-collapse:collapse;margin-top:4px">'
            f"<thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>"
            f'<div class="qos-lab-legend" style="font-size:11px;color:#555">'
            f"{html.escape(LOOPBACK_NOTE)}.</div>")


def _cell(value) -> str:
    return "" if value is None else str(value)


def _note(result: ExperimentResult) -> str:
    """How the run ended, in a few words, and whether the machine was busy meanwhile."""
    if result.in_flight:
        note = f"NOT FINISHED ({'stopped' if result.stopped else 'ended early'}): in flight is not lost"
    elif result.stopped:
        note = "stopped"
    elif result.config.late_joiner:
        note = f"late joiner got {result.delivered} old samples"
    elif result.delivered == result.published and result.lost_nothing:
        note = "nothing lost"
    else:
        note = ""
    if result.machine is not None and result.machine.busy:
        note = f"{note}; busy machine" if note else "busy machine"
    return note
