"""The course's Fast DDS set-up on live participants: localhost-only transports, chosen per range.

Each check starts a fresh child process (its sockets are its participant's alone) that reports its
discovery range, the profile file Fast DDS read and the addresses of its UDP sockets.
"""

from __future__ import annotations

import pytest

from course_helpers.core import dds_config
from course_helpers.core.dds_config import (
    DEFAULTS_PROFILE,
    RANGE_ENV,
    SLOT_PROFILE_STEM,
    TIMING_PROFILE,
    UDP_PROFILE,
    default_discovery_env,
    udp_loopback_env,
)
from course_helpers.core.waiting import HANG_S
from tests.helpers_children import report_participant_setup


def _setup_of(rt, label: str, env: dict | None = None) -> dict:
    child = rt.spawn(label, report_participant_setup, env=env)
    return child.wait_for_report("setup", 30, f"the participant set-up of {label}")


def test_a_child_gets_the_localhost_profile_listens_on_loopback_only_and_is_found(rt):
    setup = _setup_of(rt, "course_child")
    assert setup["range"] == "LOCALHOST"  # the variable children see is what the course promises
    assert setup["profile"].startswith(SLOT_PROFILE_STEM + "_")  # the localhost profile on a slot of its own
    assert setup["udp"] and set(setup["udp"]) == {"127.0.0.1"}, setup["udp"]
    rt.wait_until(lambda: "/setup_reporter" in rt.graph_nodes(), 20, "the kernel to find the child's node")


def test_the_udp_profile_is_loopback_only_too(rt):
    setup = _setup_of(rt, "udp_child", udp_loopback_env(rt.log_dir))
    assert (setup["range"], setup["profile"]) == ("LOCALHOST", UDP_PROFILE)
    assert setup["udp"] and set(setup["udp"]) == {"127.0.0.1"}, setup["udp"]
    rt.wait_until(lambda: "/setup_reporter" in rt.graph_nodes(), 20, "the kernel to find the UDP child")


def test_another_range_gets_the_timing_only_profile(rt):
    setup = _setup_of(rt, "loner_child", {RANGE_ENV: "OFF"})
    assert (setup["range"], setup["profile"]) == ("OFF", TIMING_PROFILE)


def test_fast_dds_defaults_leave_the_transports_to_rmw(rt):
    """The comparison set-up: rmw_fastrtps's own LOCALHOST transports listen on every interface."""
    setup = _setup_of(rt, "defaults_child", default_discovery_env(rt.log_dir))
    assert (setup["range"], setup["profile"]) == ("LOCALHOST", DEFAULTS_PROFILE)
    assert "0.0.0.0" in setup["udp"], setup["udp"]


def test_the_tuned_settings_are_in_the_profile_and_the_defaults_are_not():
    tuned, defaults = dds_config.profile_xml(), dds_config.profile_xml((), tuned=False)
    assert "<healthy_check_timeout_ms>300</healthy_check_timeout_ms>" in tuned
    assert '<data_reader profile_name="ros_discovery_info">' in tuned
    assert "<nanosec>100000000</nanosec></leaseAnnouncement>" in tuned
    assert '<data_writer profile_name="service">' in tuned
    # a server waits for a late client's reply reader as long as any wait for the certain (not 0.1 s)
    assert f"<max_blocking_time><sec>{int(HANG_S)}</sec><nanosec>0</nanosec></max_blocking_time>" in tuned
    assert "<sec>3</sec><nanosec>0</nanosec></leaseAnnouncement>" in defaults
    assert "ros_discovery_info" not in defaults and "transport" not in defaults and "service" not in defaults


def _fast_dds_errors(rt, tmp_path, profile: str) -> list[str]:
    """The errors Fast DDS logs (to standard output, its default consumer) while a fresh process makes
    one node with ``profile``."""
    import os
    import subprocess
    import sys

    path = tmp_path / "profile.xml"
    path.write_text(profile)
    env = {**os.environ, "FASTRTPS_DEFAULT_PROFILES_FILE": str(path),
           "ROS_DOMAIN_ID": str(rt.domain.domain_id)}
    script = ("import rclpy; rclpy.init(); rclpy.create_node('profile_reader').destroy_node(); "
              "rclpy.shutdown()")
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                          timeout=HANG_S)
    assert done.returncode == 0, done.stderr
    return [line for line in (done.stdout + done.stderr).splitlines() if "Error" in line]


def test_discovery_between_participants_of_one_process_goes_through_the_transports(rt, tmp_path):
    """Every profile the course writes keeps Fast DDS's in-process shortcut for user data only (see
    INTRAPROCESS_DELIVERY), and Fast DDS reads that setting without an error."""
    for profile in (dds_config.profile_xml(), dds_config.profile_xml(()), dds_config.profile_xml(("UDPv4",)),
                    dds_config.profile_xml((), tuned=False), dds_config.profile_xml(slot=5, domain_id=42),
                    dds_config.profile_xml(lease_s=2.0)):
        assert ("<library_settings><intraprocess_delivery>USER_DATA_ONLY</intraprocess_delivery>"
                "</library_settings>") in profile
    assert _fast_dds_errors(rt, tmp_path, dds_config.profile_xml()) == []


def test_fast_dds_names_a_misspelt_library_setting(rt, tmp_path, monkeypatch):
    """The check above can fail: a value Fast DDS does not know is an error it logs."""
    monkeypatch.setattr(dds_config, "INTRAPROCESS_DELIVERY", "USER_DATA")
    errors = _fast_dds_errors(rt, tmp_path, dds_config.profile_xml())
    assert any("intraprocess_delivery" in line for line in errors), errors


def test_a_child_on_a_slot_tells_the_kernel_last():
    """A child lists the discovery ports of participant ids 31 down to 0: the kernel (id 0, the first
    participant of its domain) hears the child's announcement last, and its answer comes back after
    the child listens (the module's docstring gives the measured difference)."""
    import xml.etree.ElementTree as ET

    from course_helpers.core.udp_sockets import discovery_port

    root = ET.fromstring(dds_config.profile_xml(slot=5, domain_id=42))
    ports = [int(port.text) for port in root.iterfind(".//{*}initialPeersList//{*}port")]
    assert ports == [discovery_port(42, i) for i in range(dds_config.PEER_IDS - 1, -1, -1)], ports
    assert ports[-1] == discovery_port(42, 0)


def test_an_unknown_transport_is_named():
    with pytest.raises(ValueError, match=r"'SHM' and/or 'UDPv4', got \['TCPv4'\]"):
        dds_config.profile_xml(("TCPv4",))


def test_a_short_lease_profile_is_private_loopback_only_and_holds_the_lease(rt, tmp_path, monkeypatch):
    """Chapter 01's short lease: written into the kernel's private folder (a name another user made
    first at the old shared path changes nothing), the course's localhost set-up otherwise, and a
    killed child leaves the graph after its 2 s lease instead of Fast DDS's 20 s."""
    import os
    import stat
    import tempfile

    from course_helpers.chapters.ch01_architecture import short_lease_env

    private = rt.log_dir  # made before the temporary folder is redirected
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # a shared temporary folder of the test's own
    # what another user could have created first at the old, predictable path
    os.mkdir(tmp_path / f"ros2-course-lease-{os.getuid()}-2.000000000.xml")
    env = short_lease_env(2.0)
    monkeypatch.undo()
    path = env[dds_config.PROFILE_ENV]
    folder = os.stat(private)
    assert os.path.dirname(path) == private
    assert folder.st_uid == os.getuid() and stat.S_IMODE(folder.st_mode) == 0o700
    setup = _setup_of(rt, "lease_child", env)
    assert setup["profile"].startswith("course_localhost_lease_") and set(setup["udp"]) == {"127.0.0.1"}
    rt.wait_until(lambda: "/setup_reporter" in rt.graph_nodes(), 20, "the kernel to find the lease child")
    rt.children()["lease_child"].kill()  # a crash: no goodbye, so only the lease removes it
    assert rt.poll_until(lambda: "/setup_reporter" not in rt.graph_nodes(), 10.0), (
        "a killed child with a 2 s lease stayed in the graph for 10 s")


@pytest.mark.parametrize("lease", [0.1, 61, "2", True])
def test_a_lease_outside_its_range_is_named(lease):
    with pytest.raises(dds_config.CourseError, match=r"lease_s must be 0.5..60 seconds"):
        dds_config.short_lease_env("/nonexistent", lease)


@pytest.mark.parametrize("lease", [0.1, 61, "2", True])
def test_a_discovery_server_lease_outside_its_range_is_named(lease):
    with pytest.raises(dds_config.CourseError, match=r"lease_s must be 0.5..60 seconds"):
        dds_config.discovery_server_profile("/nonexistent", lease)


def test_the_discovery_server_profile_keeps_it_a_server_with_its_lease(tmp_path):
    """fast-discovery-server -x FILE makes the file's default participant the server: it must say SERVER
    (the CLI sets it only without -x) and carry the lease."""
    import xml.etree.ElementTree as ET

    path = dds_config.discovery_server_profile(str(tmp_path), 1.5)
    ns = {"f": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}
    participant = ET.parse(path).getroot().find("f:participant", ns)
    assert participant.get("is_default_profile") == "true"
    config = participant.find("f:rtps/f:builtin/f:discovery_config", ns)
    assert config.findtext("f:discoveryProtocol", namespaces=ns) == "SERVER"
    lease = config.find("f:leaseDuration", ns)
    found = (lease.findtext("f:sec", namespaces=ns), lease.findtext("f:nanosec", namespaces=ns))
    assert found == ("1", "500000000")


LATE_START = """
import os, sys
os.environ.pop("FASTRTPS_DEFAULT_PROFILES_FILE", None)
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
import rclpy
from rclpy.context import Context
from course_helpers.core.dds_config import profile_comes_too_late
from course_helpers.core.runtime import CourseRuntime
print("before any participant:", profile_comes_too_late())
if sys.argv[1] == "early":
    early = Context()
    rclpy.init(context=early, domain_id=int(os.environ["ROS_DOMAIN_ID"]))
    node = rclpy.create_node("students_own", context=early)  # kept: its participant lives while it does
rt = CourseRuntime().start()
rt.stop()
"""


@pytest.mark.parametrize("first", ["early", "course"])
def test_a_participant_made_before_the_course_is_named_in_one_line(first, tmp_path):
    """Fast DDS reads the profile once per process, at its first participant: a participant made before
    the course's runtime means the course's profile cannot apply, and the runtime says so (and only then)."""
    import os
    import subprocess
    import sys

    script = tmp_path / "late.py"
    script.write_text(LATE_START)
    env = {**os.environ, "ROS_DOMAIN_ID": os.environ.get("ROS_DOMAIN_ID") or "77"}
    done = subprocess.run([sys.executable, str(script), first], capture_output=True, text=True, timeout=60,
                          env=env)
    out = done.stdout
    assert done.returncode == 0, done.stderr
    assert "before any participant: False" in out, out
    assert (dds_config.LATE_PROFILE in out) == (first == "early"), out
