"""The inductive drive (L > 0, spec §8) on the compiled kernel: its lean step against the event loop and
the Python path.

Without stops or contact, a step whose mesh rolls throughout is one kernel call
(`kernel.drive.inductive_fast_step`: the input at the substep nodes, the substeps, the guards); a step
with a mode change, the current limit starting or ending, or a stuck mesh is handed to the Python event
loop (`actuators.inductive_stepping.advance`), which locates the event and sets i = ±i_max exactly where
the limit starts to act. References: the same Simulator with the lean path switched off (the event loop
on the compiled substeps, bit for bit), and the readable Python path (every stage in Python), to 1e-12 rad
and 1e-12 A. With contact (a grasp) the compiled substeps and the Python events are compared the same way.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml

from finger_sim.actuators.drive import STUCK
from finger_sim.scene import Scene, scene_from_dict
from finger_sim.simulate import Simulator

pytest.importorskip("numba")
from finger_sim.kernel.inductive import InductiveFastStepper  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: L/R = 1.25 ms with the default 8 Ω: auto's rk6 takes 4 substeps per 1 ms step (cheap on the Python path).
INDUCTANCE = 1e-2
#: Spec §8's current limit (A), typed in again.
IMAX = 0.5
DRIVES = [{}, {"efficiency": 0.9, "backward_efficiency": 0.8}, {"efficiency": 1.0, "backward_efficiency": 1.0}]
#: Agreement asked of the compiled kernel with the Python path: rad (and rad/s), A.
TOLERANCE = 1e-12


def free_scene(drive: dict, voltage: dict | None) -> Scene:
    return scene_from_dict({"model": {"drive": {**drive, "inductance": INDUCTANCE}, "spring_stiffness": 0.2},
                            "input": {"voltage": voltage or {"type": "constant", "value": 0.0}}, "duration": 0.3,
                            "integrator": {"method": "auto", "dt": 1e-3}})


def held(k: int, dt: float) -> float:
    """The node's path: a held command per step, V (a 2 Hz sine of ±6 V, reversing the finger)."""
    return 6.0 * math.sin(2.0 * math.pi * 2.0 * k * dt)


def counting(sim: Simulator) -> list[int]:
    """[steps the lean call took, steps it handed to the event loop], counted as `sim` steps."""
    counts = [0, 0]
    call = sim._lean.call

    def counted(*args):  # type: ignore[no-untyped-def]
        out = call(*args)
        counts[out[0] != 0] += 1
        return out

    sim._lean.call = counted
    return counts


@pytest.mark.parametrize("drive", DRIVES)
@pytest.mark.parametrize("voltage", [{"type": "square", "amplitude": 3.0, "offset": 3.0, "frequency": 5.0},
                                     {"type": "sine", "amplitude": 6.0, "frequency": 3.0}, None])
def test_the_lean_step_is_the_event_loop_bit_for_bit_and_the_python_path_within_1e_12(drive, voltage):
    """Through current-limit starts and ends, reversals, sticking and breaking free; voltage=None: a held
    command per step."""
    scene = free_scene(drive, voltage)
    lean, loop, python = (Simulator(scene, kernel=k) for k in ("compiled", "compiled", "python"))
    assert isinstance(lean._lean, InductiveFastStepper) and python._lean is None
    loop._lean = None
    counts = counting(lean)
    modes, limited = set(), 0
    for k in range(scene.step_count):
        u = held(k, scene.dt) if voltage is None else None
        a, b, c = lean.step(u), loop.step(u), python.step(u)
        i_lean, i_python = lean.system.drive.i, python.system.drive.i
        assert (a.q, a.v, lean.system.drive.mode, i_lean) == (b.q, b.v, loop.system.drive.mode, loop.system.drive.i)
        assert max(abs(x - y) for x, y in zip((*a.q, *a.v), (*c.q, *c.v))) <= TOLERANCE
        assert abs(i_lean - i_python) <= TOLERANCE and lean.system.drive.mode == python.system.drive.mode
        assert lean.torque == python.torque
        modes.add(lean.system.drive.mode)
        limited += abs(i_lean) == IMAX  # set to ±i_max exactly where the limit starts to act, held there
    if voltage is not None and voltage["type"] == "square":  # 6 V from rest: u/R = 0.75 A would pass the limit
        assert limited >= 1
    assert len(modes) >= 2 or drive.get("efficiency") == 1.0
    assert counts[0] >= 0.5 * scene.step_count  # most steps lean (a self-locking mesh sticks at 0 V: the rest)
    assert counts[1] >= 1 or drive.get("efficiency") == 1.0  # the events in Python (an ideal gear has the limit only)


def test_a_stuck_mesh_is_left_to_the_event_loop_and_holds_exactly():
    """The self-locking drive driven up and stopped at 0 V: the mesh sticks at its turning point, the current
    decays through L/R, and the pose is held bit for bit; every stuck step goes through the event loop."""
    scene = free_scene({}, {"type": "step", "before": 6.0, "after": 0.0, "at": 0.1})
    lean, python = Simulator(scene, kernel="compiled"), Simulator(scene, kernel="python")
    counts = counting(lean)
    held_at, stuck = None, 0
    for _ in range(scene.step_count):
        a, c = lean.step(), python.step()
        assert max(abs(x - y) for x, y in zip((*a.q, *a.v), (*c.q, *c.v))) <= TOLERANCE
        assert abs(lean.system.drive.i - python.system.drive.i) <= TOLERANCE
        if lean.system.drive.mode == STUCK:
            held_at, stuck = held_at or a.q, stuck + 1
            assert a.q == held_at and a.v == (0.0, 0.0, 0.0)
    assert held_at is not None and lean.system.drive.i == pytest.approx(0.0, abs=1e-6)
    assert counts[1] >= stuck >= 0.5 * scene.step_count  # every stuck step handed to the event loop


def test_a_grasp_with_inductance_runs_compiled_as_on_the_python_path():
    """drive_grasp (the self-locking drive closing on the cup, then 0 V) with L > 0: contact onset, stuck
    hold and the current's decay, stepped by the node's path on both kernels."""
    data = yaml.safe_load((CONFIG / "drive_grasp.yaml").read_text())
    data["model"]["drive"] = {"inductance": INDUCTANCE}
    data["input"]["voltage"]["at"], data["duration"] = 0.12, 0.15
    scene = scene_from_dict(data)
    compiled, python = Simulator(scene, kernel="compiled"), Simulator(scene, kernel="python")
    assert compiled.kernel.startswith("numba-") and python.kernel == "python"
    modes = set()
    for _ in range(scene.step_count):
        a, c = compiled.step(), python.step()
        assert max(abs(x - y) for x, y in zip((*a.q, *a.v), (*c.q, *c.v))) <= TOLERANCE
        assert abs(compiled.system.drive.i - python.system.drive.i) <= TOLERANCE
        modes.add(compiled.system.drive.mode)
    assert STUCK in modes and compiled.system.drive.i < IMAX


def test_auto_says_which_kernel_carries_the_current():
    scene = free_scene({}, None)
    assert "each rolling step (input, substeps, guards) is one compiled call" in Simulator(scene).method_reason
    assert Simulator(scene, kernel="python").method_reason.endswith("; the Python path carries the current")


def test_auto_runs_a_short_inductive_run_offline_on_the_compiled_kernel(monkeypatch):
    """Loading numba (≈ 0.5 s) pays for itself within some 60 steps of an inductive drive (its Python step
    costs 10–40 ms), not the 20 000 steps of a torque-driven rk6 run: a 100-step run is compiled, the same
    run with L = 0 stays in Python while numba is not loaded."""
    import sys

    from finger_sim.kernel import offline_kernel

    monkeypatch.delitem(sys.modules, "numba", raising=False)  # as in a fresh process
    inductive = free_scene({}, None)
    plain = scene_from_dict({"model": {"drive": {}}, "input": {"voltage": {"type": "constant", "value": 6.0}}})
    assert offline_kernel("auto", 100, inductive) == "auto"
    assert offline_kernel("auto", 100, plain) == offline_kernel("auto", 100) == "python"
    assert offline_kernel("python", 100, inductive) == "python"
