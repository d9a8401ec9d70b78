"""``%ros2 bag record|info|play|stop`` against real nodes, and every kind of bad input as one line.

Recording runs in the background and the command returns at once; ``info`` prints what
``ros2 bag info`` prints; ``play`` publishes the bag to a real subscriber; ``record`` never writes
over an existing folder. Each bad input (a missing or damaged bag, a type this venv does not know,
a topic the bag does not hold, a name that exists) prints one ``error:`` line, returns 1, and the
runtime keeps working.
"""

from __future__ import annotations

import shutil

import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from std_msgs.msg import String

from course_helpers.core import bags
from course_helpers.nodes import Listener, Talker
from course_helpers.notebook.ros2cli import run


@pytest.fixture
def ros2(rt, capsys, tmp_path, monkeypatch):
    """``ros2('bag info x')`` -> (exit code, printed text), in ``tmp_path`` as the notebook's folder."""
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()

    def call(command: str):
        code = run(command, rt=rt)
        return code, capsys.readouterr().out

    yield call
    bags.player.stop_all()
    bags.recorder.stop_all()


@pytest.fixture
def talk_bag(rt, ros2, tmp_path):
    """A bag 'talk' of /bag_talk recorded with the magic from a 20 Hz talker: its folder."""
    rt.add(Talker, name="bag_magic_talker", topic="bag_talk", rate_hz=20.0, console=False)
    code, out = ros2("bag record -o talk /bag_talk")
    assert code == 0
    assert out == "Recording /bag_talk to 'talk' (mcap), in the background until %ros2 bag stop.\n"
    recording = bags.recordings(running_only=True)[-1]  # the command returned; the recording goes on
    rt.wait_until(lambda: recording._writer.stats.received >= 6, 10, "six recorded messages")
    code, out = ros2("bag stop")
    assert code == 0 and out.startswith("Stopped recording 'talk': ") and "dropped" not in out
    rt.remove("/bag_magic_talker")
    return tmp_path / "talk"


def test_record_info_play_round_trip(rt, ros2, talk_bag):
    written = bags.bag_info(talk_bag).message_count
    code, out = ros2("bag info talk")
    assert code == 0
    lines = out.splitlines()
    assert lines[1] == "Files:             talk.mcap" and lines[3] == "Storage id:        mcap"
    assert f"Messages:          {written}" in lines
    assert f"Topic information: Topic: /bag_talk | Type: std_msgs/msg/String | Count: {written} | " \
           "Serialization Format: cdr" in lines
    listener = rt.add(Listener, name="bag_magic_listener", topic="bag_talk", console=False)
    rt.wait_until(lambda: rt.graph.count_subscribers("/bag_talk") >= 1, 5, "the listener in the graph")
    code, out = ros2("bag play talk --rate 4")
    assert code == 0 and out.splitlines()[-1] == f"Done: {written} messages published."
    rt.wait_until(lambda: len(listener.heard) == written, 5, "every played message")
    recorded = [msg.data for _stamp, msg in bags.read(talk_bag, "/bag_talk")]
    assert listener.heard == recorded  # message for message, in order


def test_info_qos_shows_the_recorded_offers(ros2, talk_bag):
    code, out = ros2("bag info talk --qos")
    assert code == 0 and "  QoS offered: reliable, volatile" in out


def test_record_never_overwrites_and_overwrite_replaces_only_a_bag(rt, ros2, talk_bag, tmp_path):
    before = {p.name: p.read_bytes() for p in talk_bag.iterdir()}
    code, out = ros2("bag record -o talk /bag_talk")
    assert code == 1 and out == (f"error: Output folder '{talk_bag}' already exists (ros2 bag record "
                                 f"never writes over a bag); choose another name, or add --overwrite to "
                                 f"replace it\n")
    assert {p.name: p.read_bytes() for p in talk_bag.iterdir()} == before
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "mine.txt").write_text("keep me")
    code, out = ros2("bag record -o notes /bag_talk --overwrite")
    assert code == 1 and "is not a bag" in out and len(out.splitlines()) == 1
    assert (tmp_path / "notes" / "mine.txt").read_text() == "keep me"
    code, out = ros2("bag record -o talk /bag_talk --overwrite --duration 0.2 -s sqlite3")
    assert code == 0
    bags.recordings()[-1].wait()
    assert [p.suffix for p in talk_bag.iterdir() if p.name != "metadata.yaml"] == [".db3"]


def _unknown_type_bag(folder):
    """A bag whose one topic has a type no package of the venv defines."""
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection("/mystery", "mystery_msgs/msg/Thing", msgdef="int32 x",
                                           rihs01="RIHS01_" + "0" * 64)
        writer.write(connection, 1, b"\x00\x01\x00\x00\x05\x00\x00\x00")


def test_every_bad_input_is_one_line_and_the_kernel_keeps_working(rt, ros2, talk_bag, tmp_path):
    shutil.copytree(talk_bag, tmp_path / "damaged")
    (tmp_path / "damaged" / "talk.mcap").write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 40)
    _unknown_type_bag(tmp_path / "mystery")
    (tmp_path / "empty_folder").mkdir()
    cases = {
        "bag info missing": "error: no bag 'missing'",
        "bag play missing": "error: no bag 'missing'",
        "bag info empty_folder": "error: 'empty_folder' is not a bag",
        "bag play damaged": "error: cannot read the bag 'damaged'",
        "bag play mystery": "error: topic /mystery has type mystery_msgs/msg/Thing, which this venv does not",
        "bag play talk --topics /not_there": "error: topic '/not_there' is not in the bag 'talk'",
        "bag record -o talk /bag_talk": "error: Output folder",
        "bag record -o fresh": "error: Need to specify at least one option",
        "bag record -o fresh -e '('": "error: invalid --regex '('",
        "bag record -o fresh /bag_talk --storage zip": "",  # argparse's usage error (exit code 2)
    }
    for command, start in cases.items():
        code, out = ros2(command)
        if start:
            assert code == 1 and out.startswith(start) and len(out.splitlines()) == 1, (command, out)
        else:
            assert code == 2 and "invalid choice: 'zip'" in out, out
    assert not (tmp_path / "fresh").exists()
    info = bags.bag_info(tmp_path / "mystery")  # info needs no type: it reads the bag, not the messages
    assert [t.type for t in info.topics] == ["mystery_msgs/msg/Thing"]
    assert rt.running  # the runtime keeps working after every one of them
    assert rt.wait_for_messages("/bag_talk_after", String, 1, 5) if rt.add(
        Talker, name="bag_after", topic="bag_talk_after", rate_hz=20.0, console=False) else False


def test_stop_with_nothing_running_says_so(ros2):
    assert ros2("bag stop") == (0, "(nothing is being recorded or played in this kernel)\n")
