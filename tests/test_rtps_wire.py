"""RTPS on the wire (notebooks 07b and 08c): real captures with dumpcap, read with tshark's dissector.

* the QoS lab's Wi-Fi preset (400 samples, the link drops 10 % of the data datagrams): in the reliable
  run every lost sample comes back, each after a HEARTBEAT that reached the reader and an ACKNACK
  naming it that reached the writer; the best-effort run has no HEARTBEAT, no ACKNACK and no second
  copy of anything, so what the link dropped stays lost. The check fails when a link of the chain
  is taken out or put after the repair;
* one node starting beside an observer announces exactly one endpoint per DDS writer and reader of
  its participant (its node's publishers, subscriptions, 2 per service, plus the ros_discovery_info
  pair), with simple discovery and with a discovery server, and the server changes who carries them;
* an ACKNACK's or GAP's bitmap decodes in either byte order;
* nothing is left behind: no capture, no namespace holder, and after a kernel stops, no process of it
  (its Cyclone DDS participant lived in the kernel itself);
* cells marked ``# COURSE_NEEDS: tshark`` / ``cyclonedds`` are skipped with the install line.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import os
import sys

import psutil
import pytest

from course_helpers.chapters.ch07_dds import discovery_wire
from course_helpers.chapters.ch08b_lab import preset
from course_helpers.chapters.ch08b_lab.wire import WireRun, capture_run, wire_unavailable_reason
from course_helpers.core import netns, processes, rtps_capture
from course_helpers.core.dds_config import PEER_IDS
from course_helpers.core.rtps_capture import _bitmap

from .conftest import REPO
from .kernel_session import KernelSession

REASON = wire_unavailable_reason()
needs_wire = pytest.mark.skipif(REASON is not None, reason=str(REASON))


@pytest.fixture(scope="module")
def runs() -> dict[str, WireRun]:
    """The Wi-Fi preset's two runs, captured: {'best_effort': ..., 'reliable': ...}."""
    return {c.reliability: capture_run(c) for c in preset("Wi-Fi link, 10 % loss")}


@pytest.fixture(scope="module")
def counts() -> dict:
    return {setting: discovery_wire.count_discovery(setting) for setting in discovery_wire.SETTINGS}


@needs_wire
def test_every_lost_sample_of_a_reliable_run_comes_back_after_heartbeat_then_acknack(runs):
    run = runs["reliable"]
    assert run.config.loss_percent == 10 and run.result.delivered == run.result.published == 400
    assert run.lost, "the link dropped no sample of 400 at 10 %"
    assert [r.seq for r in run.repairs] == run.lost and not run.unrepaired
    for repair in run.repairs:
        assert repair.in_order, repair
        assert repair.heartbeat.frame < repair.acknack.frame < repair.resent.frame, repair
        assert repair.seq in repair.acknack.numbers and not repair.acknack.dropped
        assert repair.heartbeat.kind == "HEARTBEAT" and not repair.heartbeat.dropped
        assert all(copy.dropped for copy in repair.lost) and not repair.resent.dropped
        assert repair.waited_s > 0, repair  # the times are printed, never bounded: see 08c
    counts = run.counts()
    assert counts["DATA"][0] == 400 + run.resent
    assert run.resent >= counts["DATA"][1]  # each dropped copy was followed by another
    assert counts["ACKNACK"][0] >= 1 and counts["HEARTBEAT"][0] >= 1
    assert run.all_repaired_in_order() and not run.nothing_repaired()


@needs_wire
def test_best_effort_sends_nothing_twice_and_nobody_asks(runs):
    run = runs["best_effort"]
    counts = run.counts()
    assert run.lost, "the link dropped no sample of 400 at 10 %"
    assert counts["HEARTBEAT"] == counts["ACKNACK"] == counts["GAP"] == (0, 0)
    assert run.resent == 0 and run.repairs == [] and run.unrepaired == run.lost
    assert counts["DATA"] == (400, len(run.lost))
    assert run.result.lost_by_sequence >= len(run.lost)  # the subscriber misses at least those
    assert run.nothing_repaired() and not run.all_repaired_in_order()


@needs_wire
def test_the_repair_check_fails_when_a_link_of_the_chain_is_missing_or_late(runs):
    run = runs["reliable"]
    no_acknacks = WireRun(run.result, 0, [s for s in run.submessages if s.kind != "ACKNACK"])
    assert no_acknacks.repairs and not any(r.in_order for r in no_acknacks.repairs)
    assert not no_acknacks.all_repaired_in_order()
    no_heartbeats = WireRun(run.result, 0, [s for s in run.submessages if s.kind != "HEARTBEAT"])
    assert not no_heartbeats.all_repaired_in_order()
    first = run.repairs[0]  # every ACKNACK naming it moved after the copy that arrived
    late = [dataclasses.replace(s, frame=first.resent.frame + 0.5)
            if s.kind == "ACKNACK" and first.seq in s.numbers else s for s in run.submessages]
    late_run = WireRun(run.result, 0, sorted(late, key=lambda s: s.frame))
    moved = next(r for r in late_run.repairs if r.seq == first.seq)
    assert moved.acknack is None and not moved.in_order and not late_run.all_repaired_in_order()
    assert all(r.in_order for r in late_run.repairs if r.seq != first.seq and r.acknack is not None
               and first.seq not in r.acknack.numbers)


@needs_wire
def test_a_dropped_resend_of_a_sample_that_had_arrived_is_no_loss(runs):
    # A busy reader can ask again for a sample whose first copy waits in its socket; the link may drop
    # the copy sent again. Seen in CI: counted as lost, it was a "repair" without a lost copy.
    run = runs["reliable"]
    kept = next(s for s in run.data() if s.seq not in run.lost)
    spurious = dataclasses.replace(kept, frame=run.submessages[-1].frame + 1, dropped=True)
    again = WireRun(run.result, 0, [*run.submessages, spurious])
    assert again.lost == run.lost and again.resent == run.resent + 1
    assert again.all_repaired_in_order() and [r.seq for r in again.repairs] == run.lost


def test_sequence_number_sets_decode_in_both_byte_orders():
    assert _bitmap({"rtps.sm.seqNumber": "8", "rtps.bitmap.num_bits": "2", "rtps.bitmap": "00:00:00:40"},
                   little=True) == (8, (9,))
    assert _bitmap({"rtps.sm.seqNumber": "8", "rtps.bitmap.num_bits": "2", "rtps.bitmap": "40:00:00:00"},
                   little=False) == (8, (9,))
    assert _bitmap({"rtps.sm.seqNumber": "1", "rtps.bitmap.num_bits": "33",
                    "rtps.bitmap": "00:00:00:80:00:00:00:80"}, little=True) == (1, (1, 33))
    assert _bitmap({"rtps.sm.seqNumber": "5", "rtps.bitmap.num_bits": "0", "rtps.bitmap": ""},
                   little=True) == (5, ())


@needs_wire
@pytest.mark.parametrize("setting", discovery_wire.SETTINGS)
def test_a_starting_node_announces_one_endpoint_per_writer_and_reader(counts, setting):
    count = counts[setting]
    node = count.node_endpoints
    assert node == {"publishers": 3, "subscriptions": 0, "services": 7, "clients": 0}  # a talker
    assert count.writers == node["publishers"] + node["services"] + node["clients"] + 1
    assert count.readers == node["subscriptions"] + node["services"] + node["clients"] + 1
    assert count.announced == count.expected == 19
    assert count.sedp_submessages >= count.announced and count.spdp_datagrams >= 1
    if setting == "simple":
        assert count.spdp_ports == PEER_IDS  # every port its initial peers name
        assert count.sent_to == ["observer"] and count.observer_heard_from == ["newcomer"]
    else:
        assert count.spdp_ports == 1  # the server's
        assert count.sent_to == ["discovery server"] and count.observer_heard_from == ["discovery server"]


@needs_wire
def test_the_captures_and_namespaces_are_gone_after_each_measurement(runs, counts):
    assert processes.running(rtps_capture.GROUP) == {}
    assert processes.get(discovery_wire.NAMESPACE_LABEL, group=netns.GROUP) is None
    assert not [label for label in discovery_wire.LABELS.values() if processes.get(label)]


LEFTOVERS_CELL = """
import json, os
from course_helpers import get_runtime
from course_helpers.chapters import ch07_dds as dds
from course_helpers.chapters.ch08b_lab.link import lossy_link
from course_helpers.core import rtps_capture
from cyclonedds.domain import DomainParticipant
rt = get_runtime()
dds.cyclone_domain(rt)
participant = DomainParticipant(rt.domain.domain_id)
link = lossy_link(10)
capture = rtps_capture.start_capture(link, 'leftover_check', rtps_capture.ODD_PORTS,
                                     rtps_capture.DROP_LOG_GROUP)
with open('/proc/self/maps') as maps:
    cyclone_here = any('libddsc' in line for line in maps)
print(json.dumps({'kernel': os.getpid(), 'dumpcap': capture.child.pid, 'holder': link.pid,
                  'participants': dds.cyclone_participants(), 'cyclone_in_kernel': cyclone_here}))
"""


def _gone(pid: int, created: float) -> bool:
    try:
        return psutil.Process(pid).create_time() != created
    except psutil.NoSuchProcess:
        return True


def _children_of(kernel: int) -> list[int]:
    """Processes started for the kernel (the process layer marks them with the kernel's PID)."""
    found = []
    for process in psutil.process_iter(["pid"]):
        try:
            if process.environ().get("COURSE_PARENT_PID") == str(kernel):
                found.append(process.pid)
        except psutil.Error:
            continue
    return found


@needs_wire
@pytest.mark.skipif(importlib.util.find_spec("cyclonedds") is None, reason="cyclonedds is not installed: "
                    "pip install cyclonedds==11.0.1 (environment.txt pins it)")
def test_nothing_is_left_after_the_kernel_stops():
    session = KernelSession(cwd=os.path.join(REPO, "notebooks"))
    try:
        output, error = session.run(LEFTOVERS_CELL, timeout=90)
        assert error is None, session.traceback
        seen = json.loads(output.strip().splitlines()[-1])
        assert seen["participants"] == 1 and seen["cyclone_in_kernel"]
        started = {pid: psutil.Process(pid).create_time() for pid in (seen["dumpcap"], seen["holder"])}
        assert set(started) <= set(_children_of(seen["kernel"]))
    finally:
        code, _stderr = session.shutdown()
    assert code is not None  # the kernel, and the Cyclone DDS participant in it, ended
    assert all(_gone(pid, created) for pid, created in started.items()), "dumpcap or the namespace's holder"
    assert _children_of(seen["kernel"]) == []


def _conftest_rule():
    path = os.path.join(REPO, "notebooks", "conftest.py")
    spec = importlib.util.spec_from_file_location("notebook_rule", path)
    rule = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(rule)
    return rule


def test_cells_needing_tshark_or_cyclonedds_are_skipped_with_the_install_line(monkeypatch, tmp_path):
    rule = _conftest_rule()
    monkeypatch.setenv("PATH", str(tmp_path))  # no tshark, no dumpcap on this PATH
    reason = rule.skip_reason("# COURSE_NEEDS: tshark\nprint('captured')", {})
    assert reason.startswith("needs tshark: ") and "apt-get install tshark" in reason, reason
    monkeypatch.setitem(sys.modules, "cyclonedds", None)  # what Python does for a missing package
    monkeypatch.setitem(sys.modules, "cyclonedds.domain", None)
    reason = rule.skip_reason("# COURSE_NEEDS: cyclonedds\nimport cyclonedds", {})
    assert reason.startswith("needs cyclonedds: ") and "pip install cyclonedds==" in reason, reason
    assert rule.skip_reason("print('no needs')", {}) is None
