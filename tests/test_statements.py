"""Statements about ROS 2 that a review found wrong (issue 32) stay right.

Each case reads the cell or quiz that now makes the statement, requires the true wording and refuses
the wrong one it replaced. The source each follows is named beside it. Where a statement can be shown
live, its notebook also proves it with a claim; this guards the prose around it.
"""

from __future__ import annotations

import json
import os

import pytest
import yaml

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# (notebook, cell id, words the cell must hold, words it must not hold, the source it follows)
CELLS = [
    ("05_actions", "c004",
     ["A cancel request can come while the goal waits as well as while it runs", "SUCCEEDED or ABORTED"],
     [], "rcl_action/src/rcl_action/goal_state_machine.c: ACCEPTED and EXECUTING both take CANCEL_GOAL"),
    ("08a_quality_of_service", "ce0c3728", ["`SensorDataQoS` (best effort, depth 5)"],
     ["reliable subscription"], "robot_state_publisher/src/robot_state_publisher.cpp: joint_states "
                                "subscribed with rclcpp::SensorDataQoS()"),
    ("10_capstone", "3bf87f8c", ["best effort with depth 5"], ["RELIABLE, depth 1"],
     "the same robot_state_publisher subscription"),
    ("06_parameters", "c027", ["Components come from rclcpp's `rclcpp_components`; rclpy has none"],
     ["every node runs as its own process"], "rclcpp_components exists for C++ only"),
    ("01_architecture", "c09", ["rclpy has neither"], ["standard feature of every node"],
     "components and intra-process communication are rclcpp's"),
    ("02_nodes_and_executors", "c22",
     ["(no DDS participant yet)", "first node also creates its DDS participant"],
     ["context and DDS participant"], "rmw_fastrtps_shared_cpp: the participant is made with the "
                                      "context's first node (rmw_create_node)"),
    ("02_nodes_and_executors", "cpp-source", [], ["textbook"], "students never see a textbook's snippet"),
]


def _cell(notebook: str, cell_id: str) -> str:
    with open(os.path.join(REPO, "notebooks", f"{notebook}.ipynb"), encoding="utf-8") as f:
        cells = json.load(f)["cells"]
    found = [cell for cell in cells if cell.get("id") == cell_id]
    assert found, f"{notebook} has no cell {cell_id!r}: the statement moved, so update this test"
    return "".join(found[0]["source"])


@pytest.mark.parametrize("notebook, cell_id, holds, not_any, source", CELLS,
                         ids=[f"{nb}-{cid}" for nb, cid, *_ in CELLS])
def test_the_cell_says_what_ros_2s_source_does(notebook, cell_id, holds, not_any, source):
    text = " ".join(_cell(notebook, cell_id).split())  # line breaks in the prose do not matter
    missing = [words for words in holds if " ".join(words.split()) not in text]
    wrong = [words for words in not_any if words in text]
    assert not missing and not wrong, f"{notebook} {cell_id} (per {source}): missing {missing}, wrong {wrong}"


def test_the_launch_quiz_says_each_node_action_is_a_process_and_composition_is_cpp():
    with open(os.path.join(REPO, "course_helpers", "notebook", "quizzes", "06_parameters.yaml"),
              encoding="utf-8") as f:
        text = yaml.safe_dump(yaml.safe_load(f), width=10_000)
    assert "rclcpp_components" in text and "every node runs as its own process" not in text.lower(), text
