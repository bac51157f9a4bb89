"""Helpers of the multi-process ROS tests: a probe node in the test process and parameter calls through
the real parameter services. The ``graph`` and ``probe`` fixtures built on them are in conftest.py."""

from __future__ import annotations

import time


class Probe:
    """An rclpy node in the test process, on the graph's domain, that records what it receives."""

    def __init__(self, domain_id: int):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("probe", context=self.ctx)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.received: dict[str, list] = {}
        self._param_clients: dict[str, object] = {}

    def listen(self, topic: str, msg_type, qos=50) -> None:
        self.received[topic] = []
        self.node.create_subscription(msg_type, topic, lambda m: self.received[topic].append(
            (time.monotonic(), m)), qos)

    def spin_for(self, seconds: float, until=None) -> bool:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.01)
            if until is not None and until():
                return True
        return until is None

    def call(self, srv_type, name: str, timeout: float = 10.0):
        client = self.node.create_client(srv_type, name)
        assert client.wait_for_service(timeout_sec=timeout), f"service {name} not available"
        future = client.call_async(srv_type.Request())
        self.spin_for(timeout, until=future.done)
        assert future.done(), f"no answer from {name}"
        return future.result()

    def set_param(self, node: str, name: str, value, timeout: float = 20.0):
        """Set one parameter of ``/node`` through its set_parameters service; the SetParametersResult.
        ``value``: a float (sent as a double) or a ready rcl_interfaces ParameterValue."""
        from rcl_interfaces.msg import Parameter
        from rcl_interfaces.srv import SetParameters

        client = self._param_clients.get(node)
        if client is None:
            client = self.node.create_client(SetParameters, f"/{node}/set_parameters")
            assert client.wait_for_service(timeout_sec=timeout), f"/{node}/set_parameters not available"
            self._param_clients[node] = client
        value = value if not isinstance(value, float | int) else double(value)
        future = client.call_async(SetParameters.Request(parameters=[Parameter(name=name, value=value)]))
        assert self.spin_for(10.0, until=future.done), f"no answer setting {node}.{name}"
        return future.result().results[0]

    def get_params(self, node: str, names: list[str]) -> list:
        """The ParameterValues of ``names`` of ``/node`` through its get_parameters service."""
        from rcl_interfaces.srv import GetParameters

        get = self.node.create_client(GetParameters, f"/{node}/get_parameters")
        assert get.wait_for_service(timeout_sec=10.0)
        future = get.call_async(GetParameters.Request(names=names))
        assert self.spin_for(10.0, until=future.done)
        return list(future.result().values)

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


def double(x: float):
    """A double ParameterValue."""
    from rcl_interfaces.msg import ParameterType, ParameterValue

    return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=float(x))


def string(s: str):
    """A string ParameterValue."""
    from rcl_interfaces.msg import ParameterType, ParameterValue

    return ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=s)
