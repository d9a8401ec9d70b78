"""``%ros2 bag record|info|play|stop``: rosbag2's verbs on the course's bag engine (:mod:`.core.bags`).

* ``record -o NAME TOPIC... [--all] [-e REGEX] [-s mcap|sqlite3] [--duration S] [--overwrite]``
  starts recording in the background of the kernel and returns at once; it ends after
  ``--duration`` or at ``%ros2 bag stop``. Like ``ros2 bag record`` it never writes over an existing
  folder (``--overwrite``, a course addition, replaces a former bag);
* ``info NAME [--qos]`` prints what ``ros2 bag info`` prints (``--qos`` adds each topic's recorded offers);
* ``play NAME [--rate R] [--clock [HZ]] [--loop] [--topics T...]`` publishes the bag at its recorded
  pace; the cell waits until it has played (the stop button stops it), except with ``--loop``, which
  plays in the background until ``%ros2 bag stop``;
* ``stop [NAME]`` (a course addition: in a shell, Ctrl-C) ends recordings and playbacks.

A bag's NAME is a folder, relative to the notebook's own folder like any file.
"""

from __future__ import annotations

import datetime

from course_helpers.core import bags
from course_helpers.core.bags import player, recorder
from course_helpers.core.bags.reader import resolve
from course_helpers.core.bags.writer import DEFAULT_STORAGE, STORAGES
from course_helpers.core.units import format_bytes
from course_helpers.core.waiting import wait_until
from course_helpers.notebook.ros2cli._common import (
    Verb,
    _non_negative_float,
    _positive_float,
    add_verb_table,
    option,
)


def _names(topics: list[str]) -> str:
    return ", ".join(topics) if len(topics) < 6 else f"{', '.join(topics[:5])} and {len(topics) - 5} more"


def _record(rt, args):
    topics = list(args.topics_positional or []) + list(args.topics or [])
    output = args.output or datetime.datetime.now().strftime("rosbag2_%Y_%m_%d-%H_%M_%S")
    bags.record(rt, output, topics, all_topics=args.all, regex=args.regex, storage=args.storage,
                            duration=args.duration, overwrite=args.overwrite, use_sim_time=args.use_sim_time)
    parts = [_names(topics)] if topics else []
    parts += [f"the topics matching {args.regex!r}"] if args.regex else []
    what = "every topic" if args.all else " and ".join(parts)
    until = f"for {args.duration:g} s" if args.duration else "until %ros2 bag stop"
    print(f"Recording {what} to '{output}' ({args.storage}), in the background {until}.")
    return None


def _summary(recording) -> str:
    stats = recording.stats
    dropped = f", {stats.dropped} dropped (the writer fell behind)" if stats.dropped else ""
    return (f"'{recording.path.name}': {stats.written} messages of {len(stats.per_topic)} topic(s) written, "
            f"{format_bytes(stats.bytes_written)}{dropped}")


def _info(rt, args):
    print(bags.format_info(bags.bag_info(args.bag_path), qos=args.qos))
    return None


def _play(rt, args):
    playback = bags.play(rt, args.bag_path, rate=args.rate, topics=args.topics or None, loop=args.loop,
                         clock_hz=args.clock or None, delay_s=args.delay, start_paused=False)
    info = playback.info
    count = sum(t.count for t in info.topics if t.name in playback.topics)
    clock = f", publishing /clock at {args.clock:g} Hz" if args.clock else ""
    if args.loop:
        print(f"Playing '{args.bag_path}' in a loop at rate {args.rate:g}{clock}, in the background "
              f"(%ros2 bag stop ends it).")
        return None
    print(f"Playing {count} messages of {len(playback.topics)} topic(s) from '{args.bag_path}' "
          f"({info.duration_ns / 1e9:.2f} s of bag time) at rate {args.rate:g}{clock}...")
    try:
        wait_until(playback.finished.is_set, info.duration_ns / 1e9 / args.rate + args.delay + 30.0,
                   f"the playback of '{args.bag_path}'")
    except KeyboardInterrupt:
        playback.stop()
        raise
    if playback.error is not None:
        return f"error: playing '{args.bag_path}' failed: {playback.error}"
    print(f"Done: {sum(playback.published.values())} messages published.")
    return None


def _stop(rt, args):
    chosen = resolve(args.bag_path) if args.bag_path else None
    stopped = 0
    for recording in recorder.recordings():
        if chosen is not None and recording.path != chosen:
            continue
        was_running = recording.running
        if not was_running and chosen is None:
            continue
        recording.stop()
        print(("Stopped recording " if was_running else "Already ended: recording ") + _summary(recording))
        stopped += 1
    for playback in player.playbacks(running_only=True):
        if chosen is not None and playback.path != chosen:
            continue
        published = sum(playback.stop().values())
        print(f"Stopped playing '{playback.path.name}' after {published} messages.")
        stopped += 1
    if not stopped:
        print(f"(no recording or playback of '{args.bag_path}' in this kernel)" if args.bag_path
              else "(nothing is being recorded or played in this kernel)")
    return None


BAG_PATH = option("bag_path", help="The bag: a folder with metadata.yaml, relative to the notebook's folder")
VERBS = (
    Verb("record", "Record ROS data to a bag (in the background of the kernel)", _record, (
        option("topics_positional", nargs="*", default=[], metavar="TOPIC", help="Topics to record"),
        option("--topics", nargs="+", default=[], metavar="TOPIC",
               help="Topics to record (same as positional)"),
        option("-o", "--output", help="Destination folder of the bag (default: rosbag2_<date>-<time>)"),
        option("-a", "--all", action="store_true", help="Record every topic (hidden ones left out)"),
        option("-e", "--regex", help="Record the topics that match a regular expression"),
        option("-s", "--storage", choices=sorted(STORAGES), default=DEFAULT_STORAGE,
               help=f"Storage format (default: {DEFAULT_STORAGE}; sqlite3 writes rosbag2's older format)"),
        option("--duration", type=_positive_float, metavar="S",
               help="Stop recording after S seconds (course addition; otherwise %%ros2 bag stop)"),
        option("--overwrite", action="store_true",
               help="Replace an existing bag of the same name (course addition; ros2 bag record refuses)"),
        option("--use-sim-time", action="store_true",
               help="Stamp messages with the recorder's ROS time from /clock instead of the receive time"))),
    Verb("info", "Print information about a bag", _info, (
        BAG_PATH,
        option("--qos", action="store_true", help="Also show the QoS each topic's publishers offered "
                                                  "(course addition)"))),
    Verb("play", "Play back ROS data from a bag", _play, (
        BAG_PATH,
        option("-r", "--rate", type=_positive_float, default=1.0, metavar="R",
               help="Rate at which to play back messages (default: 1)"),
        option("--topics", nargs="+", default=[], metavar="TOPIC", help="Topics to play (default: all)"),
        option("--clock", type=_positive_float, nargs="?", const=40.0, default=0.0, metavar="HZ",
               help="Publish /clock from the bag's time at HZ (default when given: 40 Hz)"),
        option("-l", "--loop", action="store_true",
               help="Play again from the start at the end, in the background until %%ros2 bag stop"),
        option("-d", "--delay", type=_non_negative_float, default=0.0, metavar="S",
               help="Wait S seconds before playing"))),
    Verb("stop", "Stop the kernel's recordings and playbacks (course addition: Ctrl-C in a shell)", _stop, (
        option("bag_path", nargs="?", help="Only this bag (default: every one running)"),)),
)


def add_verbs(parser):
    add_verb_table(parser, VERBS)
