"""Helpers shared by the tests that talk to a node over DDS (import after `pytest.importorskip("rclpy")`)."""

from __future__ import annotations

from std_srvs.srv import SetBool, Trigger

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


def resume(client, node_name: str, timeout: float | None = None, process=None) -> str:
    """Resume a node started paused; its answer. A no-op ~/pause(true) goes first and is answered:
    from then on the node's ~/pause server has matched our client, so the resume's answer cannot be
    lost to discovery. A node that then runs its scene in a moment and exits (realtime_factor 0) may
    exit before its answer leaves: given its `process`, an unanswered resume of a node that has exited
    with status 0 counts as answered (it ran to the end of its scene, which only a resume starts)."""
    kwargs = {} if timeout is None else {"timeout": timeout}
    assert client.call(SetBool, f"{node_name}/pause", SetBool.Request(data=True), **kwargs).success
    try:
        answer = client.call(SetBool, f"{node_name}/pause", SetBool.Request(data=False), **kwargs)
    except AssertionError:
        if process is None or process.running() or process.wait(0.0) != 0:
            raise
        return "exited at the end of its scene"
    assert answer.success, answer.message
    return answer.message
