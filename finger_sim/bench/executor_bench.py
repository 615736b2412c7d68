"""rclpy's SingleThreadedExecutor against rclpy.experimental.EventsExecutor, receiving commands at 1 kHz.

    python -m finger_sim.bench.executor_bench [--seconds 12] [--rounds 3] [--domain-id 140]

A publisher process sends std_msgs/Float64 at 1 kHz of wall time on /cmd (system-default QoS, as
a controller's motor_torque); a receiver process (one subscription, a counting callback, as the
node's executor thread) spins one executor with `spin_once` for --seconds, then prints its
messages received and CPU (utime + stime of the process). Receivers alternate single, events,
single, events … (A B A B); the table gives each run and the medians of the CPU µs per message.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time

from finger_sim.bench.processes import executor_command

KINDS = ("single", "events")
PERIOD_S = 0.001  # the publisher's period, wall s
START_TIMEOUT_S = 120.0  # wall s for a receiver to see its first message

_PUBLISHER = """
import sys, time, rclpy
from rclpy.qos import qos_profile_system_default
from std_msgs.msg import Float64
rclpy.init(); node = rclpy.create_node("cmd_pub")
pub = node.create_publisher(Float64, "/cmd", qos_profile_system_default)
period, msg, start, k = float(sys.argv[1]), Float64(), time.perf_counter(), 0
while True:
    k += 1; msg.data = float(k); pub.publish(msg)
    time.sleep(max(0.0, start + k * period - time.perf_counter()))
"""

_RECEIVER = """
import os, sys, time, rclpy
from rclpy.qos import qos_profile_system_default
from std_msgs.msg import Float64
kind, seconds = sys.argv[1], float(sys.argv[2])
rclpy.init(); node = rclpy.create_node("cmd_recv"); got = [0]
node.create_subscription(Float64, "/cmd", lambda msg: got.__setitem__(0, got[0] + 1), qos_profile_system_default)
if kind == "events":
    from rclpy.experimental import EventsExecutor
    executor = EventsExecutor(context=node.context)
else:
    from rclpy.executors import SingleThreadedExecutor
    executor = SingleThreadedExecutor(context=node.context)
executor.add_node(node)
while got[0] == 0:
    executor.spin_once(timeout_sec=0.1)
n0, t0, w0 = got[0], os.times(), time.perf_counter()
while time.perf_counter() - w0 < seconds:
    executor.spin_once(timeout_sec=0.1)
t1, w1 = os.times(), time.perf_counter()
print(got[0] - n0, (t1.user + t1.system) - (t0.user + t0.system), w1 - w0)
"""


def receive(kind: str, seconds: float, env: dict[str, str]) -> tuple[int, float, float]:
    """One receiver run: messages, CPU s, wall s."""
    done = subprocess.run([sys.executable, "-c", _RECEIVER, kind, str(seconds)], env=env, capture_output=True,
                          text=True, timeout=seconds + START_TIMEOUT_S, check=True)
    n, cpu, wall = done.stdout.split()
    return int(n), float(cpu), float(wall)


def main(argv: list[str] | None = None) -> int:
    args, env = executor_command("executor_bench", __doc__, argv, seconds=12.0, rounds=3, domain_id=140)
    publisher = subprocess.Popen([sys.executable, "-c", _PUBLISHER, str(PERIOD_S)], env=env,
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    per_message: dict[str, list[float]] = {k: [] for k in KINDS}
    try:
        time.sleep(1.0)
        print("| run | executor | messages received (per s) | CPU s | CPU µs per message | cores |")
        print("|---|---|---:|---:|---:|---:|")
        for r in range(args.rounds):
            for kind in KINDS:
                n, cpu, wall = receive(kind, args.seconds, env)
                per_message[kind].append(1e6 * cpu / max(n, 1))
                print(f"| {r + 1} | {kind} | {n} ({n / wall:.0f}) | {cpu:.2f} | {per_message[kind][-1]:.0f} | {cpu / wall:.3f} |")
    finally:
        publisher.terminate()
        publisher.wait()
    single, events = (statistics.median(per_message[k]) for k in KINDS)
    print(f"median CPU µs per message: single {single:.0f}, events {events:.0f} (events/single {events / single:.2f})")
    print(f"load average at end: {os.getloadavg()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
