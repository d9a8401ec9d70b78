"""Reference solutions of chapter 04 (services); CI checks them with ``checks.ch04_services``."""

from __future__ import annotations

from course_interfaces.srv import AddTwoInts
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from std_msgs.msg import Float32
from std_srvs.srv import Trigger

LOW_BATTERY_PERCENT = 20.0  # below this the battery is reported as low


class BatteryMonitor(Node):
    """Exercise 04.1: keeps the latest battery level and reports it through a Trigger service."""

    def __init__(self):
        super().__init__('battery_monitor')
        self.level = None  # latest reading [%]; None until the first message
        self.subscription = self.create_subscription(Float32, 'battery_level', self.on_level, 10)
        self.service = self.create_service(Trigger, 'battery_status', self.on_status)

    def on_level(self, msg: Float32) -> None:
        self.level = msg.data

    def on_status(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        if self.level is None:
            response.success = False
            response.message = 'no reading yet'
        elif self.level < LOW_BATTERY_PERCENT:
            response.success = False
            response.message = f'battery low: {self.level:.0f}%'
        else:
            response.success = True
            response.message = f'battery at {self.level:.0f}%'
        return response


class SumRelay(Node):
    """Exercise 04.2: answers add_via_relay by asking add_two_ints, without blocking the executor."""

    def __init__(self):
        super().__init__('sum_relay')
        # An async callback keeps its callback group busy while it awaits, so the client that
        # delivers the backend's answer must be in a group of its own.
        self.backend = self.create_client(AddTwoInts, 'add_two_ints',
                                          callback_group=MutuallyExclusiveCallbackGroup())
        self.service = self.create_service(AddTwoInts, 'add_via_relay', self.on_request)

    async def on_request(self, request: AddTwoInts.Request, response: AddTwoInts.Response):
        # `await` hands the thread back to the executor until the backend's answer arrives
        answer = await self.backend.call_async(AddTwoInts.Request(a=request.a, b=request.b))
        response.sum = answer.sum
        return response
