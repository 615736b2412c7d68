"""CPU µs per `Simulator.step` of a stateful actuator in the slot: a first-order torque lag, T = 20 ms.

    python -m finger_sim.bench.stateful_bench python|auto     # the lag declared by its law (`LawActuator`)
    PYTHONPATH=<a checkout> python finger_sim/bench/stateful_bench.py lawless   # hand-written methods

`lawless` is the lag of test/core/test_state_layout.py (its `torque` and `rates` written as methods: the
Python path, the only one before the compiled stateful step), so it runs against an older checkout too;
`python` and `auto` are the same lag declared by its law, on the Python path and under auto (compiled).
Per case, 6 whole runs in this process, `time.process_time`; prints the median and minimum of the last 5.
Run the variants as alternating processes and compare their medians (docs/actuator_state.md).
"""

from __future__ import annotations

import functools
import statistics
import sys
import time
from pathlib import Path

import yaml

from finger_sim.actuators.base import Actuator
from finger_sim.scene import scene_from_dict
from finger_sim.simulate import Simulator
from finger_sim.state_layout import Slot

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: The lag's time constant, s.
LAG = 0.02
#: Runs per case; the first loads the code and is left out.
RUNS = 6
PAPER = {"model": {"spring_stiffness": 0.001}, "input": {"torque": {"type": "ramp", "offset": 0.001, "slope": 0.01}},
         "duration": 0.3, "integrator": {"method": "rk6", "dt": 1e-3}}
STOPS = {"model": {"spring_stiffness": 0.001, "joint_limits": {"mcp": [0.0, 0.8]}, "restitution": 0.0},
         "input": {"torque": {"type": "sine", "amplitude": 0.01, "frequency": 2.0}}, "duration": 0.6,
         "integrator": {"method": "rk6", "dt": 1e-3}}


def cases() -> dict[str, tuple[dict, int]]:
    """name → (scene data, steps): the paper's scene, the stops with rests, config/grasp_cylinder.yaml (contact)."""
    with open(CONFIG / "grasp_cylinder.yaml") as f:
        grasp = yaml.safe_load(f)
    grasp.update(duration=0.35, integrator={"method": "rk6", "dt": 2.5e-4})
    return {"paper": (PAPER, 300), "stops_rest": (STOPS, 600), "grasp": (grasp, 1400)}


class HandWrittenLag(Actuator):
    """τ_a' = (u − τ_a)/T with its torque and rates written as methods (no declared law)."""

    name = "lag"
    slots = (Slot("torque", "N·m"),)

    def __init__(self, time_constant: float) -> None:
        self.time_constant = time_constant

    def initial(self) -> tuple[float, ...]:
        return (0.0,)

    def torque(self, system, t, q, v, u, own):  # type: ignore[no-untyped-def]
        return own[0]

    def rates(self, t, q, v, u, own):  # type: ignore[no-untyped-def]
        return ((u - own[0]) / self.time_constant,)


def lag_torque(p, t, q0, q1, q2, v0, v1, v2, u, own):  # type: ignore[no-untyped-def]
    """The lag's torque on θ1, N·m: its slot."""
    return own[0]


def lag_rates(p, t, q0, q1, q2, v0, v1, v2, u, own):  # type: ignore[no-untyped-def]
    """τ_a' = (u − τ_a)/T, N·m/s; p = (T s,)."""
    return ((u - own[0]) / p[0],)


@functools.cache
def declared_lag_class() -> type[Actuator]:
    """The same lag declared by its law (`actuators.base.LawActuator`, which an older checkout lacks): it
    has a compiled form. One class, one law: compiled once per process."""
    from finger_sim.actuators.base import ActuatorLaw, LawActuator

    class DeclaredLag(LawActuator):
        name = "lag"
        slots = (Slot("torque", "N·m"),)
        law = ActuatorLaw(lag_torque, lag_rates)

        def __init__(self, time_constant: float) -> None:
            self.time_constant = time_constant

        def initial(self) -> tuple[float, ...]:
            return (0.0,)

        def kernel_params(self) -> tuple[float, ...]:
            return (self.time_constant,)

    return DeclaredLag


def main(variant: str) -> None:
    make = (lambda: HandWrittenLag(LAG)) if variant == "lawless" else (lambda: declared_lag_class()(LAG))
    kernel = "python" if variant == "lawless" else variant
    for case, (data, steps) in cases().items():
        times = []
        for _ in range(RUNS):
            sim = Simulator(scene_from_dict(data), kernel=kernel, actuator=make())
            start = time.process_time()
            for _ in range(steps):
                sim.step()
            times.append((time.process_time() - start) / steps * 1e6)
        print(f"{variant} {case} kernel={sim.kernel} µs/step median {statistics.median(times[1:]):.2f} "
              f"min {min(times[1:]):.2f}", flush=True)


if __name__ == "__main__":
    if len(sys.argv) != 2 or sys.argv[1] not in ("lawless", "python", "auto"):
        sys.exit("usage: stateful_bench.py lawless|python|auto")
    main(sys.argv[1])
