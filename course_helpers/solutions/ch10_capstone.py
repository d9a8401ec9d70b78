"""Reference solution of chapter 10 (capstone), checked by ``course_helpers/checks/ch10_capstone.py``.

:class:`FleetSafetyMonitor` is the robot's safety monitor, extended to obey the fleet manager's
e-stop as well:

* it subscribes to ``/fleet/estop``, an absolute name: the one topic of the whole fleet, not a
  topic under the robot's namespace;
* with the e-stop's QoS, RELIABLE + TRANSIENT_LOCAL: a monitor that starts after the fleet was
  stopped still receives the fleet's current state;
* a fleet stop engages the robot's e-stop; the fleet's release releases it only if the fleet was
  what engaged it (an operator's or the LIDAR's stop stays until an operator releases it);
* while the fleet stop holds, the operator's ``~/engage`` service refuses to release.
"""

from __future__ import annotations

from course_interfaces.msg import EStop
from std_srvs.srv import SetBool

from course_helpers.chapters.ch10_capstone import SafetyMonitor
from course_helpers.chapters.ch10_capstone.channels import ESTOP_QOS


class FleetSafetyMonitor(SafetyMonitor):
    """The robot's safety monitor, which also obeys the fleet manager's e-stop on /fleet/estop."""

    def __init__(self, namespace='/robot1'):
        super().__init__(namespace)
        self.fleet_stopped = False  # is the fleet's e-stop engaged right now?
        self.fleet_subscription = self.create_subscription(
            EStop, '/fleet/estop', self.on_fleet_estop, ESTOP_QOS)

    def on_fleet_estop(self, msg: EStop) -> None:
        self.fleet_stopped = msg.engaged
        if msg.engaged and not self.current.engaged:
            self.publish_estop(True, f'fleet stop: {msg.reason}', 'fleet')
        elif not msg.engaged and self.current.engaged and self.current.source == 'fleet':
            self.publish_estop(False, '', 'fleet')

    def on_engage(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        if not request.data and self.fleet_stopped:
            response.success = False
            response.message = 'the fleet stop holds: only the fleet manager can release it'
            return response
        return super().on_engage(request, response)
