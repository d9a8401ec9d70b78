"""Chapter 07: discovery tuning (default against the course's announcement period), what announcing
costs, and the transport measurement's fastest round trip.

Real child processes over real Fast DDS. Bounds are loose: the machine has 2 shared cores.
"""

from __future__ import annotations

import json
import os
import socket

import pytest

from course_helpers import CourseError
from course_helpers.chapters import ch07_dds as dds
from course_helpers.chapters.ch07_dds.discovery import DiscoveryTiming
from course_helpers.core.dds_config import DEFAULT_ANNOUNCEMENT_S, PEER_IDS
from course_helpers.core.verdict import reusing
from tests.timing import assert_timing

# measures time (rates, latencies, DDS events): make test's timing stage, few workers beside it
pytestmark = pytest.mark.timing

NOTEBOOK = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                        "notebooks", "07_dds_and_discovery.ipynb")


def test_discovery_comparison_uses_two_own_domains_and_bounds_the_tuned_wait(rt):
    comparison = dds.compare_discovery(rt, repeats=3)
    assert set(comparison.timings) == set(dds.SETTINGS)
    for setting in dds.SETTINGS:
        assert len(comparison.timings[setting]) == 3 and comparison.missed(setting) == 0
        assert all(t.create_node_s > 0 for t in comparison.timings[setting])
    default_bound_s = 2 * DEFAULT_ANNOUNCEMENT_S  # two of Fast DDS's periods; the course's: 0.1 s, so 1 s
    assert_timing(
        f"the course's setting finds the anchor within 1 s, Fast DDS's within {default_bound_s:g} s",
        reusing(comparison, lambda: dds.compare_discovery(rt, repeats=3)),
        lambda c: max(c.seconds("course")) < 1.0 and max(c.seconds("Fast DDS default")) < default_bound_s,
        show=lambda c: f"slowest: course {max(c.seconds('course')):.2f} s, "
                       f"Fast DDS {max(c.seconds('Fast DDS default')):.2f} s")
    domains = dds.discovery_settings._comparison_domains()
    assert len(set(domains)) == 2 and rt.domain.domain_id not in domains
    assert dds.discovery_settings._comparison_domains() == domains  # re-running reuses them
    assert not rt.children()  # anchors and probes are stopped


def test_comparison_statistics_count_a_probe_that_never_found_as_the_timeout():
    found = DiscoveryTiming(0.2, 0.25, 0.3, 0.3, 0.31)
    lost = DiscoveryTiming(0.2, None, None, None, None)
    comparison = dds.DiscoveryComparison({"Fast DDS default": [found, lost], "course": [found, found]}, 5.0)
    assert comparison.seconds("Fast DDS default") == [pytest.approx(0.1), 5.0]
    assert comparison.missed("Fast DDS default") == 1 and comparison.missed("course") == 0
    assert comparison.percentile("Fast DDS default", 1.0) == 5.0
    assert comparison.percentile("course", 0.5) == pytest.approx(0.1)


def test_compare_discovery_refuses_bad_repeats(rt):
    for repeats in (1, 21, 2.5, True):
        with pytest.raises(CourseError):
            dds.compare_discovery(rt, repeats=repeats)


def test_announcements_of_a_lone_participant_are_counted_and_the_ports_freed(rt):
    traffic = assert_timing(
        "the lone participant announces to each port more often than every third of Fast DDS's period",
        lambda: dds.measure_announcements(rt, seconds=1.0),
        lambda t: t.period_s is not None and t.period_s < DEFAULT_ANNOUNCEMENT_S / 3,
        show=lambda t: f"every {t.period_s} s")
    assert len(traffic.senders) == 1  # one participant: the lone listener
    # its own port is one we could not listen on, whatever id Fast DDS gave it
    assert traffic.own_id is not None and traffic.own_id in traffic.held_ids
    listened_in_range = sorted(pid for pid in traffic.arrivals if pid < PEER_IDS)
    assert traffic.ports_reached == listened_in_range  # every peer port it could reach, and no other
    assert traffic.datagram_bytes > 100
    domain = dds.discovery_settings._comparison_domains()[0]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:  # the listening sockets are closed
        sock.bind(("127.0.0.1", dds.discovery_port(domain, traffic.ports_reached[0])))
    with pytest.raises(CourseError):
        dds.listen_to_announcements(domain, seconds=0.0)


def test_a_port_held_by_another_program_moves_the_lone_participant_and_the_measurement_says_so(rt):
    domain = dds.discovery_settings._comparison_domains()[0]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as holder:
        holder.bind(("127.0.0.1", dds.discovery_port(domain, 0)))  # participant 0's port, as in a CI run
        traffic = dds.measure_announcements(rt, seconds=0.5)
    assert traffic.own_id not in (None, 0) and traffic.held_by_others == [0]  # it took another id's ports
    assert traffic.own_id in traffic.held_ids and len(traffic.senders) == 1
    assert traffic.ports_reached == sorted(pid for pid in traffic.arrivals if pid < PEER_IDS)


def test_fastest_round_trip_is_never_slower_than_the_median(rt):
    result = dds.measure_transports(rt, sizes=(1000,), round_trips=3, transports=("intra-process",))
    assert 0 < result.fastest_ms("intra-process", 1000) <= result.one_way_ms("intra-process", 1000)


def test_notebook_prose_no_longer_says_what_the_measurements_contradict():
    with open(NOTEBOOK, encoding="utf-8") as handle:
        cells = json.load(handle)["cells"]
    text = "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "markdown")
    for stale in ("new in Jazzy", "Nothing can be lost", "nothing can be lost", "few hundred milliseconds",
                  "stays close to it up to", "solutions/dds.py"):
        assert stale not in text, stale
    assert "**Iron**" in text and "count, not a measurement" in text
    hood = "## Deep dive (optional): under the hood"
    for taught in ("## 7. Security", "governance", "permissions", "enclave", "ROS_SECURITY_STRATEGY",
                   hood, "SPDP", "SEDP", "lease"):
        assert taught in text, taught
    assert "(section 7)" in text and "## 7. Security" in text  # the pointer of section 1 leads somewhere
    assert text.index("## 7. Security") < text.index("## 8. Exercise") < text.index(hood)
    assert text.index("leaseAnnouncement") > text.index(hood)  # tuning only in the optional part
    code = "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "code")
    assert "compare_discovery" in code and "show_solution('ch07_dds', 'PrivateRobot'" in code
