"""When a DDS participant exists: not after ``rclpy.init()``, but from a context's first node to its last.

rmw_fastrtps creates a context's participant with its first node and deletes it with its last
(:mod:`course_helpers.core.participants` names the sources). :class:`ParticipantWatch` shows it from
outside the context: at each step a cell takes (``watch.step('rclpy.init()')``), it records what this
process holds:

* its UDP sockets (psutil): a participant binds its ports when it is created and closes them when it is
  deleted, so the sockets read right after a step are that step's;
* the Fast DDS shared-memory files it maps;
* its participants as the runtime's graph lists them (each has one ``ros_discovery_info`` writer). The
  graph learns of a new or departed participant by discovery, a moment later: a step waits until the graph
  lists as many participants of this process as the process holds ``ros_discovery_info`` reader ports
  (7000-7399, one per participant that rmw_fastrtps creates: ``udp_sockets.GRAPH_PORTS``).

A node that an earlier cell dropped while it sat in a reference cycle is destroyed by Python's cyclic
garbage collector, at whatever allocation triggers it. If it was its context's last node, that deletes a
participant and closes its sockets in the middle of some later step. So the watch collects garbage before
its first record and before each step's: a step's record holds what the step itself did.
"""

from __future__ import annotations

import gc
from dataclasses import dataclass, field

from rclpy.node import Node

from course_helpers.core.errors import CourseError
from course_helpers.core.mapped_files import shm_files
from course_helpers.core.participants import Participant, participant_of, participants_of_process
from course_helpers.core.shm_ports import port_number
from course_helpers.core.udp_sockets import classify_port, is_graph_port, udp_sockets
from course_helpers.core.waiting import wait_until

GRAPH_CATCH_UP_S = 10.0  # s; bounds a hang only: the graph follows a participant's start or end at once


@dataclass(frozen=True)
class Footprint:
    """What this process held after one step."""

    label: str
    sockets: frozenset[tuple[str, int]]  # (address, port) of each UDP socket
    shm: frozenset[str]  # the Fast DDS shared-memory files mapped
    participants: tuple[Participant, ...]  # this process's participants, as the runtime's graph lists them
    nodes: dict[str, Participant] = field(default_factory=dict)  # the participant of each node of the step


class ParticipantWatch:
    """Records this process's sockets, shared memory and participants after each step of a cell.

    ``rt`` is the course runtime: its graph is the observer, and its own participant (already there)
    tells which participants in the graph belong to this process. The first record, 'before', is taken
    at once.
    """

    def __init__(self, rt):
        self.rt = rt
        self.domain_id = rt.domain.domain_id
        self.process = participant_of(rt, rt.graph.get_fully_qualified_name()).process
        self.steps: list[Footprint] = []
        self.step("before")

    def step(self, label: str, *nodes: Node) -> Footprint:
        """Record what this process holds now, under ``label``; for each of ``nodes``, its participant.

        Waits until the graph agrees with the sockets (see the module docstring) and lists each node.
        """
        if not isinstance(label, str) or not label or label in self.labels():
            raise CourseError(f"a step needs a label of its own, e.g. 'first node'; got {label!r} "
                              f"(taken: {', '.join(self.labels())})")
        gc.collect()  # an earlier cell's dropped node is destroyed now, not during a later step
        sockets = frozenset(udp_sockets())
        shm = frozenset(shm_files())
        expected = sum(1 for _address, port in sockets if is_graph_port(port))
        found: list[list[Participant]] = [[]]

        def graph_agrees() -> bool:
            found[0] = participants_of_process(self.rt.graph, self.process)
            return len(found[0]) == expected

        wait_until(graph_agrees, GRAPH_CATCH_UP_S,
                   f"the graph to list {expected} participant(s) of this process, one per port on 7000-7399")
        of_nodes = {node.get_fully_qualified_name(): participant_of(self.rt, node.get_fully_qualified_name(),
                                                                    GRAPH_CATCH_UP_S) for node in nodes}
        footprint = Footprint(label, sockets, shm, tuple(found[0]), of_nodes)
        self.steps.append(footprint)
        return footprint

    def labels(self) -> list[str]:
        return [footprint.label for footprint in self.steps]

    def __getitem__(self, label: str) -> Footprint:
        for footprint in self.steps:
            if footprint.label == label:
                return footprint
        raise CourseError(f"no step {label!r}; the steps are: {', '.join(self.labels())}")

    def _previous(self, label: str) -> Footprint:
        index = self.labels().index(self[label].label)
        if index == 0:
            raise CourseError(f"{label!r} is the first record: nothing came before it")
        return self.steps[index - 1]

    def opened(self, label: str) -> list[tuple[str, int]]:
        """The UDP sockets that step ``label`` opened, sorted by port."""
        return sorted(self[label].sockets - self._previous(label).sockets, key=lambda s: (s[1], s[0]))

    def closed(self, label: str) -> list[tuple[str, int]]:
        """The UDP sockets that step ``label`` closed, sorted by port."""
        return sorted(self._previous(label).sockets - self[label].sockets, key=lambda s: (s[1], s[0]))

    def mapped(self, label: str) -> list[str]:
        """The shared-memory files that this process mapped during step ``label``, sorted."""
        return sorted(self[label].shm - self._previous(label).shm)

    def own_ports_mapped(self, label: str) -> list[str]:
        """The port files of :meth:`mapped` whose port this process listens on (UDP) after step ``label``:
        its own participants'. The rest are peers' ports, which the participants already here (the
        runtime's) map whenever they write to a peer, whatever the step does."""
        listening = {port for _address, port in self[label].sockets}
        return [name for name in self.mapped(label) if port_number(name) in listening]

    def new_participants(self, label: str) -> list[Participant]:
        """The participants of this process that the graph lists after step ``label`` and not before it."""
        return sorted(set(self[label].participants) - set(self._previous(label).participants))

    def gone_participants(self, label: str) -> list[Participant]:
        """The participants of this process that left the graph during step ``label``."""
        return sorted(set(self._previous(label).participants) - set(self[label].participants))

    def participant(self, fqn: str) -> Participant:
        """The participant that a step recorded for node ``fqn`` ('/first')."""
        for footprint in self.steps:
            if fqn in footprint.nodes:
                return footprint.nodes[fqn]
        raise CourseError(f"no step recorded node {fqn!r}: name the node in its step, "
                          "watch.step('first node', first)")

    def created(self, label: str) -> Participant | None:
        """The participant that step ``label`` created, or None: the step opened one port on 7000-7399 and
        mapped shared memory, and the graph lists one more participant of this process."""
        graph_ports = [port for _address, port in self.opened(label) if is_graph_port(port)]
        new, gone = self.new_participants(label), self.gone_participants(label)
        if len(graph_ports) == 1 and self.mapped(label) and len(new) == 1 and not gone:
            return new[0]
        return None

    def deleted(self, label: str) -> Participant | None:
        """The participant that step ``label`` deleted, or None: the step closed one port on 7000-7399,
        and one participant of this process left the graph."""
        graph_ports = [port for _address, port in self.closed(label) if is_graph_port(port)]
        new, gone = self.new_participants(label), self.gone_participants(label)
        if len(graph_ports) == 1 and len(gone) == 1 and not new:
            return gone[0]
        return None

    def unchanged(self, label: str) -> bool:
        """True if step ``label`` opened or closed no UDP socket and left the participants in the graph."""
        return not (self.opened(label) or self.closed(label) or self.new_participants(label)
                    or self.gone_participants(label))

    def show(self) -> None:
        """Print a line per step (sockets, shared-memory files, this process's participants in the graph),
        and under it what the step opened and closed, and the participant of each node it named."""
        print(f"{'after':<18} {'UDP sockets':>11}  {'shm files':>9}  participants of this process (graph)")
        for index, footprint in enumerate(self.steps):
            print(f"{footprint.label:<18} {len(footprint.sockets):>11}  {len(footprint.shm):>9}  "
                  f"{len(footprint.participants)}")
            if index == 0:
                continue
            previous = self.steps[index - 1]
            for sign, sockets in (("+", self.opened(footprint.label)), ("-", self.closed(footprint.label))):
                for address, port in sockets:
                    meaning = classify_port(port, self.domain_id)
                    print(f"{'':<4}{sign} UDP {address + ':' + str(port):<21} {meaning}")
            for sign, names in (("+", footprint.shm - previous.shm), ("-", previous.shm - footprint.shm)):
                for name in sorted(names):
                    print(f"{'':<4}{sign} shm {name}")
            for fqn, participant in sorted(footprint.nodes.items()):
                print(f"{'':<4}node {fqn} is in participant {participant}")
