"""Helpers shared by the tests that talk to a node over DDS (import after `pytest.importorskip("rclpy")`)."""

from __future__ import annotations

from std_srvs.srv import Trigger

from finger_sim.ros import conversions


def stamp(msg) -> int:
    """A message's time, ns: its header's stamp, or a /clock message's clock."""
    return conversions.from_time(msg.header.stamp if hasattr(msg, "header") else msg.clock)


def values(msg) -> dict[str, str]:
    """The key-values of a DiagnosticStatus as a dict."""
    return {kv.key: kv.value for kv in msg.values}


def start_when_heard(client, node_name: str, *received: list) -> None:
    """Advance a paused node one step at a time until a message of each topic reaches us: from
    then on the node's publishers and our subscriptions are matched, and nothing is lost for lack
    of it. (Stepping is the node's one path, so the steps taken here are part of the run.)"""

    def heard():
        if all(received):
            return True
        client.call(Trigger, f"{node_name}/step")
        return False

    client.wait_for(heard, f"the first messages from {node_name}")
