"""The %ros2 commands against real nodes over Fast DDS (no mocks), and the IPython magic itself."""

from __future__ import annotations

import _thread
import re
import threading
import time

import pytest
import yaml
from rclpy.action import ActionServer
from rclpy.qos import QoSDurabilityPolicy, QoSProfile, QoSReliabilityPolicy
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger
from test_msgs.action import Fibonacci
from test_msgs.msg import UnboundedSequences

from course_helpers.core.errors import CourseError
from course_helpers.nodes import Listener, Talker
from course_helpers.notebook.ros2cli import message_to_yaml, run, set_message_fields
from tests.timing import assert_timing


@pytest.fixture
def ros2(rt, capsys):
    """``ros2('topic list')`` -> (exit code, printed text), running against the test runtime."""
    capsys.readouterr()

    def call(command: str):
        code = run(command, rt=rt)
        return code, capsys.readouterr().out

    return call


def _lines(text: str) -> list[str]:
    return text.splitlines()


def _talker(rt, rate_hz=10.0, **kwargs):
    node = rt.add(Talker, name="mg_talker", topic="mg_chatter", rate_hz=rate_hz, **kwargs)
    rt.wait_until(lambda: rt.graph.count_publishers("/mg_chatter") >= 1, 5, "the talker's publisher")
    return node


# ---------------------------------------------------------------------- node
def test_node_list_and_info(rt, ros2):
    _talker(rt)
    rt.add(Listener, name="mg_listener", topic="mg_chatter")
    rt.wait_for_node("/mg_listener")

    code, out = ros2("node list")
    assert code == 0
    assert {"/mg_talker", "/mg_listener"} <= set(_lines(out))
    assert "/_course_runtime" not in _lines(out)  # hidden
    assert "/_course_runtime" in _lines(ros2("node list -a")[1])

    code, out = ros2("node info /mg_talker")
    lines = _lines(out)
    assert code == 0 and lines[0] == "/mg_talker"
    sections = ["  Subscribers:", "  Publishers:", "  Service Servers:", "  Service Clients:",
                "  Action Servers:", "  Action Clients:"]
    assert [line for line in lines if line in sections] == sections
    publishers = lines[lines.index("  Publishers:"):lines.index("  Service Servers:")]
    assert "    /mg_chatter: std_msgs/msg/String" in publishers
    assert "    /mg_talker/list_parameters: rcl_interfaces/srv/ListParameters" in lines

    lines = _lines(ros2("node info /mg_listener")[1])
    assert lines[lines.index("  Subscribers:") + 1] == "    /mg_chatter: std_msgs/msg/String"

    code, out = ros2("node info /mg_nobody")
    assert code == 1 and "Unable to find node '/mg_nobody'" in out


# ---------------------------------------------------------------------- topic list/info/type
def test_topic_list_info_type(rt, ros2):
    _talker(rt)
    rt.add(Listener, name="mg_listener", topic="mg_chatter")
    rt.wait_until(lambda: rt.graph.count_subscribers("/mg_chatter") >= 1, 5, "the listener")

    assert "/mg_chatter" in _lines(ros2("topic list")[1])
    assert "/mg_chatter [std_msgs/msg/String]" in _lines(ros2("topic list -t")[1])
    assert " * /mg_chatter [std_msgs/msg/String] 1 publisher" in _lines(ros2("topic list -v")[1])

    code, out = ros2("topic info /mg_chatter")
    assert code == 0
    assert _lines(out) == ["Type: std_msgs/msg/String", "Publisher count: 1", "Subscription count: 1"]

    out = ros2("topic info mg_chatter -v")[1]  # relative names resolve against '/', like ros2cli
    for expected in ["Type: std_msgs/msg/String", "Publisher count: 1", "Node name: mg_talker",
                     "Node namespace: /", "Topic type: std_msgs/msg/String", "Endpoint type: PUBLISHER",
                     "Endpoint type: SUBSCRIPTION", "QoS profile:", "  Reliability: RELIABLE",
                     "  Durability: VOLATILE", "  Lifespan: Infinite", "  Deadline: Infinite",
                     "  Liveliness: AUTOMATIC", "  Liveliness lease duration: Infinite",
                     "Subscription count: 1"]:
        assert expected in _lines(out), expected
    assert re.search(r"^GID: [0-9a-f]{2}(\.[0-9a-f]{2})+$", out, re.M)
    assert re.search(r"^  History \(Depth\): ", out, re.M)

    assert ros2("topic type /mg_chatter") == (0, "std_msgs/msg/String\n")
    code, out = ros2("topic info /mg_nothing")
    assert code == 1 and "Unknown topic '/mg_nothing'" in out


# ---------------------------------------------------------------------- echo and QoS
def test_echo_count_once_and_field(rt, ros2):
    _talker(rt)
    code, out = ros2("topic echo /mg_chatter --count 2")
    assert code == 0
    blocks = out.split("---\n")
    assert len(blocks) == 3 and blocks[2] == ""
    assert all(re.fullmatch(r"data: hello \d+\n", block) for block in blocks[:2])

    code, out = ros2("topic echo /mg_chatter std_msgs/msg/String --once --field data")
    assert code == 0 and re.fullmatch(r"hello \d+\n---\n", out)


def test_echo_incompatible_qos_warns_and_receives_nothing(rt, ros2):
    _talker(rt, qos=QoSProfile(depth=10, reliability=QoSReliabilityPolicy.BEST_EFFORT))

    code, out = ros2("topic echo /mg_chatter --qos-reliability reliable --duration 1.5")
    assert code == 0
    assert re.search(r"\[WARN\] \[\d+\.\d+\] \[_ros2cli_echo\]: New publisher discovered on topic "
                     r"'/mg_chatter', offering incompatible QoS\. No messages will be received from it\. "
                     r"Last incompatible policy: RELIABILITY", out), out
    assert "data:" not in out

    code, out = ros2("topic echo /mg_chatter --qos-reliability best_effort --count 1")
    assert code == 0 and "data: hello" in out and "incompatible" not in out

    code, out = ros2("topic echo /mg_chatter --count 1")  # adapts to the best-effort publisher
    assert code == 0 and "data: hello" in out and "incompatible" not in out


def test_echo_adapts_to_transient_local_publisher(rt, ros2):
    node = rt.node("mg_latched")
    latched = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
    node.create_publisher(String, "mg_latched", latched).publish(String(data="retained"))
    rt.wait_until(lambda: rt.graph.count_publishers("/mg_latched") == 1, 5, "the latched publisher")

    assert ros2("topic echo /mg_latched --count 1") == (0, "data: retained\n---\n")  # late joiner gets it
    code, out = ros2("topic echo /mg_latched --qos-durability volatile --duration 0.7")
    assert code == 0 and "data:" not in out and "no message received" in out


# ---------------------------------------------------------------------- pub, hz, bw
def test_pub_times_reaches_a_listener(rt, ros2):
    listener = rt.add(Listener, name="mg_listener", topic="mg_pub")
    code, out = ros2('topic pub /mg_pub std_msgs/msg/String "{data: hi}" --times 3 --rate 20')
    assert code == 0
    assert "publisher: beginning loop" in out
    assert "publishing #3: std_msgs.msg.String(data='hi')" in out
    rt.wait_until(lambda: len(listener.heard) >= 3, 5, "three messages at the listener")
    assert "publishing #4" not in out  # the command's own count: it wrote three, and its writer is gone
    assert listener.heard == ["hi", "hi", "hi"]


def test_pub_nested_yaml_and_bad_values(rt, ros2):
    from geometry_msgs.msg import Twist

    received = []
    rt.node("mg_base").create_subscription(Twist, "mg_cmd_vel", received.append, 10)
    code, _out = ros2('topic pub /mg_cmd_vel geometry_msgs/msg/Twist "{linear: {x: 0.5}, angular: {z: 0.1}}" '
                      "--once")
    assert code == 0
    rt.wait_until(lambda: received, 5, "the Twist")
    assert (received[0].linear.x, received[0].linear.y, received[0].angular.z) == (0.5, 0.0, 0.1)

    code, out = ros2('topic pub /mg_cmd_vel geometry_msgs/msg/Twist "{linear: {q: 1}}" --once')
    assert code == 1 and out.startswith("error: ") and "has no field 'linear.q'" in out
    code, out = ros2('topic pub /mg_cmd_vel geometry_msgs/msg/Twist "{linear: {x: fast}}" --once')
    assert code == 1 and "needs a number" in out
    code, out = ros2("topic pub /mg_cmd_vel std_srvs/srv/SetBool")
    assert code == 1 and "not a message type" in out
    code, out = ros2("topic pub /mg_cmd_vel std_msgs/msg/String --once")
    assert code == 1 and "has type geometry_msgs/msg/Twist, not std_msgs/msg/String" in out
    assert "/_ros2cli_pub" not in rt.graph_nodes(include_hidden=True)


@pytest.mark.timing
def test_hz_reports_the_publisher_rate(rt, ros2):
    _talker(rt, rate_hz=10.0)

    def hz_output():
        code, out = ros2("topic hz /mg_chatter --duration 2.5")
        assert code == 0
        rates = [float(r) for r in re.findall(r"^average rate: (\d+\.\d{3})$", out, re.M)]
        assert rates, out
        return out, rates[-1]

    out, _ = assert_timing("`%ros2 topic hz` reports the 10 Hz talker at 5 to 15 Hz", hz_output,
                           lambda said: 5.0 < said[1] < 15.0, show=lambda said: f"{said[1]:.1f} Hz")
    assert re.search(r"^\tmin: \d+\.\d{3}s max: \d+\.\d{3}s std dev: \d+\.\d{5}s window: \d+$", out, re.M)


def test_bw_reports_bytes(rt, ros2):
    _talker(rt, rate_hz=10.0)
    code, out = ros2("topic bw /mg_chatter --duration 1.6")
    assert code == 0 and out.startswith("Subscribed to [/mg_chatter]\n")
    assert re.search(r"^\d+ B/s from \d+ messages\n\tMessage size mean: \d+ B min: \d+ B max: \d+ B$",
                     out, re.M)


def test_interrupted_echo_cleans_up(rt, ros2):
    _talker(rt)
    timer = threading.Timer(0.5, _thread.interrupt_main)  # what the notebook's stop button does
    timer.start()
    try:
        started = time.monotonic()
        code, out = ros2("topic echo /mg_chatter --duration 10 --field data")
    finally:
        timer.cancel()
    assert code == 130 and time.monotonic() - started < 5
    assert "Traceback" not in out
    rt.wait_until(lambda: "/_ros2cli_echo" not in rt.graph_nodes(include_hidden=True), 5, "cleanup")
    assert rt.get("/mg_talker")  # ROS keeps running


# ---------------------------------------------------------------------- services
def test_service_list_type_call(rt, ros2):
    node = rt.node("mg_server")

    def set_flag(request, response):
        response.success = request.data
        response.message = f"flag is {request.data}"
        return response

    node.create_service(SetBool, "mg_set_flag", set_flag)
    node.create_service(Trigger, "mg_trigger",
                        lambda _request, _response: Trigger.Response(success=True, message="ok"))
    rt.wait_until(lambda: any(n == "/mg_trigger" for n, _ in rt.graph.get_service_names_and_types()), 5,
                  "the services")

    assert {"/mg_set_flag", "/mg_trigger"} <= set(_lines(ros2("service list")[1]))
    assert "/mg_set_flag [std_srvs/srv/SetBool]" in _lines(ros2("service list -t")[1])
    assert ros2("service type /mg_set_flag") == (0, "std_srvs/srv/SetBool\n")
    assert ros2("service info /mg_set_flag") == (
        0, "Type: std_srvs/srv/SetBool\nClients count: 0\nServices count: 1\n")
    client = node.create_client(SetBool, "mg_set_flag")
    rt.wait_until(lambda: rt.graph.count_clients("/mg_set_flag") == 1, 5, "the client in the graph")
    assert "Clients count: 1\n" in ros2("service info mg_set_flag")[1]
    node.destroy_client(client)
    assert "Unknown service '/mg_nowhere'" in ros2("service info /mg_nowhere")[1]

    code, out = ros2('service call /mg_set_flag std_srvs/srv/SetBool "{data: true}"')
    assert code == 0
    assert "requester: making request: std_srvs.srv.SetBool_Request(data=True)\n\n" in out
    assert "response:\nstd_srvs.srv.SetBool_Response(success=True, message='flag is True')\n" in out

    code, out = ros2("service call /mg_trigger std_srvs/srv/Trigger")
    assert code == 0 and "Trigger_Response(success=True, message='ok')" in out

    code, out = ros2("service call /mg_nobody std_srvs/srv/Trigger --timeout 0.3")
    assert code == 1 and "did not become available" in out


# ---------------------------------------------------------------------- actions
def test_action_list_info_send_goal(rt, ros2):
    node = rt.node("mg_fib_server")

    def execute(goal_handle):
        sequence = [0, 1]
        for i in range(1, goal_handle.request.order):
            sequence.append(sequence[i] + sequence[i - 1])
            goal_handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
        goal_handle.succeed()
        return Fibonacci.Result(sequence=sequence)

    node.fibonacci_server = ActionServer(node, Fibonacci, "mg_fibonacci", execute)
    from rclpy.action import get_action_names_and_types

    rt.wait_until(lambda: any(n == "/mg_fibonacci" for n, _ in get_action_names_and_types(rt.graph)), 5,
                  "the action server")

    assert "/mg_fibonacci [test_msgs/action/Fibonacci]" in _lines(ros2("action list -t")[1])
    code, out = ros2("action info /mg_fibonacci")
    assert code == 0
    assert _lines(out) == ["Action: /mg_fibonacci", "Action clients: 0", "Action servers: 1",
                           "    /mg_fib_server"]
    assert "    /mg_fibonacci: test_msgs/action/Fibonacci" in _lines(ros2("node info /mg_fib_server")[1])

    code, out = ros2('action send_goal /mg_fibonacci test_msgs/action/Fibonacci "{order: 5}" --feedback')
    assert code == 0, out
    assert "Sending goal:\n     order: 5\n" in out
    assert re.search(r"^Goal accepted with ID: [0-9a-f]{32}$", out, re.M)
    assert out.count("Feedback:\n    sequence:\n") >= 1
    result = out.split("Result:\n    ", 1)[1]
    assert result.startswith("sequence:\n- 0\n- 1\n- 1\n- 2\n- 3\n- 5\n")
    assert out.rstrip().endswith("Goal finished with status: SUCCEEDED")
    rt.wait_until(lambda: _lines(ros2("action info /mg_fibonacci")[1])[1] == "Action clients: 0", 5,
                  "the temporary action client to go")


# ---------------------------------------------------------------------- parameters
def test_param_list_get_set_dump(rt, ros2):
    node = rt.node("mg_params")
    node.declare_parameter("rate_hz", 2.0)
    node.declare_parameter("robot_name", "r2")
    node.declare_parameter("gains.kp", 1.5)

    code, out = ros2("param list /mg_params")
    assert code == 0
    assert {"  gains.kp", "  rate_hz", "  robot_name", "  use_sim_time"} <= set(_lines(out))
    assert "/mg_params:" in _lines(ros2("param list")[1])
    assert "  rate_hz (type: double)" in _lines(ros2("param list /mg_params --param-type")[1])

    assert ros2("param get /mg_params rate_hz") == (0, "Double value is: 2.0\n")
    assert ros2("param get /mg_params robot_name") == (0, "String value is: r2\n")
    assert ros2("param set /mg_params rate_hz 5.0") == (0, "Set parameter successful\n")
    assert node.get_parameter("rate_hz").value == 5.0
    assert ros2("param get /mg_params rate_hz --hide-type") == (0, "5.0\n")
    code, out = ros2("param set /mg_params rate_hz fast")
    assert code == 0 and out.startswith("Setting parameter failed")

    code, out = ros2("param dump /mg_params")
    assert code == 0
    dumped = yaml.safe_load(out)
    assert dumped["/mg_params"]["ros__parameters"]["gains"] == {"kp": 1.5}
    assert dumped["/mg_params"]["ros__parameters"]["robot_name"] == "r2"
    assert dumped["/mg_params"]["ros__parameters"]["rate_hz"] == 5.0

    assert _lines(ros2("param describe /mg_params rate_hz")[1])[:2] == ["Parameter name: rate_hz",
                                                                         "  Type: double"]
    assert ros2("param get /mg_nobody rate_hz") == (1, "Node not found\n")


# ---------------------------------------------------------------------- interfaces
def test_interface_show_and_list(ros2):
    code, out = ros2("interface show geometry_msgs/msg/Twist")
    assert code == 0
    assert out.startswith("# This expresses velocity")
    assert "Vector3  linear\n\tfloat64 x\n\tfloat64 y\n\tfloat64 z\nVector3  angular\n" in out

    assert "#" not in ros2("interface show geometry_msgs/msg/Twist --no-comments")[1]
    out = ros2("interface show std_srvs/srv/SetBool")[1]
    assert _lines(out)[0].startswith("bool data") and "---" in _lines(out)
    out = ros2("interface show test_msgs/action/Fibonacci")[1]
    assert _lines(out).count("---") == 2 and "int32 order" in out
    assert ros2("interface show std_msgs/String")[1].rstrip().endswith("string data")

    out = ros2("interface list")[1]
    assert {"Messages:", "Services:", "Actions:", "    std_msgs/msg/String", "    std_srvs/srv/SetBool",
            "    test_msgs/action/Fibonacci"} <= set(_lines(out))

    code, out = ros2("interface show std_msgs/msg/Nope")
    assert code == 1 and out.startswith("error: unknown interface type 'std_msgs/msg/Nope'")


# ---------------------------------------------------------------------- usage errors
def test_bad_commands_print_usage_not_tracebacks(ros2):
    code, out = ros2("topic")
    assert code == 2
    assert "usage: ros2 topic" in out and "{list,info,type,find,echo,hz,bw,pub}" in out
    assert "the following arguments are required" in out

    code, out = ros2("bogus list")
    assert code == 2 and "invalid choice: 'bogus'" in out
    for command in ("node", "topic", "service", "action", "param", "interface"):
        assert command in out

    assert "did you mean" not in out  # nothing is close to 'bogus'
    code, out = ros2("nodez list")  # a typo: the closest command is named
    assert code == 2 and "invalid choice: 'nodez'" in out and "did you mean 'node'?" in out, out
    code, out = ros2("topic lst")
    assert code == 2 and "did you mean 'list'?" in out, out

    code, out = ros2("topic echo")
    assert code == 2 and "usage: ros2 topic echo" in out and "required: topic_name" in out
    code, out = ros2("topic hz /x --window 0")
    assert code == 2 and "whole number >= 1" in out
    code, out = ros2("topic echo /x --qos-reliability sometimes")
    assert code == 2 and "invalid choice: 'sometimes'" in out
    code, out = ros2('topic pub /x std_msgs/msg/String "{data: oops')
    assert code == 2 and out.startswith("error: ")
    code, out = ros2("topic echo /bad-name std_msgs/msg/String")
    assert code == 1 and out.startswith("error: invalid topic name")

    code, out = ros2("")
    assert code == 0 and "usage: ros2" in out
    code, out = ros2("param -h")
    assert code == 0 and "{list,get,set,dump,describe}" in out
    assert "Traceback" not in out


# ---------------------------------------------------------------------- message <-> YAML helpers
def test_message_yaml_helpers():
    msg = set_message_fields(UnboundedSequences(), {
        "float64_values": [1, 2.5], "string_values": ["a", "b: c"],
        "basic_types_values": [{"int32_value": 3, "bool_value": True}]})
    assert list(msg.float64_values) == [1.0, 2.5]
    assert msg.basic_types_values[0].int32_value == 3
    text = message_to_yaml(msg)
    assert "float64_values:\n- 1.0\n- 2.5\n" in text and "- 'b: c'\n" in text
    assert yaml.safe_load(text)["basic_types_values"][0]["int32_value"] == 3
    assert "'<sequence type: double, length: 2>'" in message_to_yaml(msg, no_arr=True)
    with pytest.raises(CourseError, match="int32_value"):
        set_message_fields(UnboundedSequences(), {"basic_types_values": [{"int32_value": "many"}]})


# ---------------------------------------------------------------------- the IPython magic
def test_magic_in_a_real_ipython_shell(rt, capsys):
    from IPython.core.interactiveshell import InteractiveShell
    from traitlets.config import Config

    config = Config()
    config.HistoryManager.hist_file = ":memory:"
    shell = InteractiveShell.instance(config=config)
    shell.run_line_magic("load_ext", "course_helpers.notebook.magics")
    assert "ros2" in shell.magics_manager.magics["line"]
    assert "ros2" in shell.magics_manager.magics["cell"]

    _talker(rt)
    capsys.readouterr()
    assert shell.run_line_magic("ros2", "topic list -t") is None
    assert "/mg_chatter [std_msgs/msg/String]" in _lines(capsys.readouterr().out)

    received = []
    rt.node("mg_magic_sink").create_subscription(String, "mg_magic", received.append, 10)
    shell.user_ns["greeting"] = "EXPANDED"  # IPython would expand $greeting / {greeting}; %ros2 must not
    shell.run_line_magic("ros2", 'topic pub /mg_magic std_msgs/msg/String "{data: $greeting}" --once')
    rt.wait_until(lambda: received, 5, "the message published by the magic")
    assert received[0].data == "$greeting"

    capsys.readouterr()
    shell.run_cell_magic("ros2", "", "node list\n# a comment\n\ntopic type /mg_chatter\n")
    out = capsys.readouterr().out
    assert "/mg_talker" in _lines(out) and "std_msgs/msg/String" in _lines(out)

    shell.run_line_magic("ros2", "topic bogus")
    out = capsys.readouterr().out
    assert "usage: ros2 topic" in out and "Traceback" not in out
