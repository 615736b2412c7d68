"""The shipped actuator (the drive, spec §8) against the slot's promise that its compiled form is its
Python law: at random states, voltages and every mesh mode, the compiled q'' (`kernel.drive.driven_accelerations`)
and, rolling, the compiled guards (`kernel.drive.drive_guards`) equal the Python path's (`DrivenSystem.accelerations`,
`actuators.stepping._guards` without a compiled model) to AGREEMENT of their size; NaN where the flank is not
unique on both. The effects' counterpart is test_effect_conformance.py; whole runs of both kernels are
compared in test_drive.py.

With inductance (L > 0, the winding current a state): at random states, currents (both sides of the limit)
and voltages, the compiled rates (q'', i') and guards (`kernel.drive.inductive_rates`, `inductive_guards`) equal
the Python law's (`DrivenSystem.mesh` at the current, `Drive.current_rate`, `inductive_stepping._guards`), and
one compiled step of n substeps (`kernel.inductive.CompiledInductiveRungeKutta`) equals the Python one
(`actuators.inductive.InductiveRungeKutta`) under a profile and under an input evaluated in Python.

No −∇V check: the drive stores no potential energy (its energies, ½ J_m ω_m² and ½ L i², are kinetic and
magnetic, functions of q' and i, not of q), so there is no V whose gradient its torque could be held to; its
torque is not conservative. Its energy law is the mesh's: in each rolling mode, where the mode's conditions hold (turn and flank guards ≥ 0), the compiled q''
solves §8's law c τ_g + N² J_m θ1'' = N k_t i with τ_g entering as a torque on θ1 alone (the §4 solve under
τ_g, written here from `FingerSystem`), and the mesh is passive: its loss τ_a ω_m − τ_g θ1' ≥ 0.

Drives: the shipped drive scenes' and an ideal gear, with the paper's spring and the cup (contact in the
force sum).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from finger_sim import kinematics
from finger_sim.actuators import inductive_stepping, stepping
from finger_sim.actuators.drive import BACK, DRIVE, STUCK
from finger_sim.actuators.inductive import InductiveRungeKutta
from finger_sim.dynamics import FingerSystem
from finger_sim.errors import SimulationDiverged
from finger_sim.integrators import METHODS
from finger_sim.kernel.drive import drive_guards, driven_accelerations, inductive_guards, inductive_rates
from finger_sim.kernel.inductive import CompiledInductiveRungeKutta
from finger_sim.kernel.layout import model_array
from finger_sim.scene import load_scene, scene_from_dict
from finger_sim.simulate import Simulator

CONFIG = Path(__file__).resolve().parents[2] / "config"
SAMPLES = 300  # random states per drive and mode
AGREEMENT = 1e-13  # compiled vs Python, relative to the largest component
SPEED = 5.0  # rad/s: the range of random velocities
VOLTAGE = 8.0  # V: the range of random voltages, past the 6 V supply (the clamp's both sides)
CUP = {"name": "cup", "type": "circle", "center": [0.065, 0.040], "radius": 0.012}


def _scenes() -> list[tuple[str, object]]:
    shipped = [(p.stem, load_scene(p)) for p in sorted(CONFIG.glob("*.yaml")) if p.name != "finger_node.yaml"]
    ideal = scene_from_dict({"model": {"drive": {"efficiency": 1.0, "backward_efficiency": 1.0}},
                             "objects": [CUP], "input": {"voltage": {"type": "constant", "value": 6.0}}})
    return [(name, s) for name, s in shipped if s.drive is not None] + [("ideal_gear_cup", ideal)]


SCENES = _scenes()
INDUCTANCE = 1e-2  # H: L/R = 1.25 ms at the spec's 8 Ω
#: the drive scenes with inductance: the winding current is a state
INDUCTIVE = [(f"{name}_inductive", dataclasses.replace(s, drive=dataclasses.replace(s.drive, inductance=INDUCTANCE)))
             for name, s in SCENES]
CURRENT = 1.2  # of i_max: the range of random currents (the limit's both sides)
STEP_SAMPLES = 40  # random states per inductive drive and mode for a whole step
SUBSTEPS = 3
DT = 1e-3  # s
LAW = 1e-12  # §8's mesh law at the compiled q'', relative to its largest term (τ_g is recovered from q'')


def _states(scene, seed: int):
    """Assembled poses over the assembly range, random rates and voltages."""
    rng = np.random.default_rng(seed)
    low, high = kinematics.assembly_range(scene.params)
    for theta1 in rng.uniform(low, high, SAMPLES).tolist():
        q = tuple(kinematics.assemble(scene.params, theta1))
        v = tuple(rng.uniform(-SPEED, SPEED, 3).tolist())
        yield q, v, float(rng.uniform(-VOLTAGE, VOLTAGE)), float(rng.choice([-1.0, 1.0]))


def _in_mode(scene, mode: int):
    """The Python path's driven system of `scene` with its mesh in `mode`, and its compiled model (whose mode
    slot follows the drive's)."""
    system = Simulator(scene, kernel="python").system
    model = model_array(system)
    assert model is not None
    system.drive.mode = mode  # mirrored into the model's mode slot
    return system, model


def _close(want, got) -> bool:
    if any(math.isnan(x) for x in want):
        return all(math.isnan(x) for x in got)
    size = max([abs(x) for x in want if math.isfinite(x)] + [0.0])
    return all(x == y if math.isinf(x) else abs(x - y) <= AGREEMENT * size for x, y in zip(want, got))


def test_the_shipped_drive_scenes_are_checked() -> None:
    assert {name for name, _ in SCENES} >= {"drive_grasp", "drive_grasp_backdrivable", "ideal_gear_cup"}


@pytest.mark.parametrize("mode", [DRIVE, BACK, STUCK])
@pytest.mark.parametrize(("name", "scene"), SCENES, ids=[n for n, _ in SCENES])
def test_compiled_drive_equals_python(name: str, scene, mode: int) -> None:
    system, model = _in_mode(scene, mode)
    drive = system.drive
    assert drive.kernel_model is None  # the guards below take the Python branch
    moving = 0
    for q, v, u, direction in _states(scene, seed=mode + 1):
        drive.direction, drive.guard_cache = direction, None
        want = system.accelerations(0.0, q, v, u)[0]
        got = driven_accelerations(model, 0.0, *q, *v, u)
        assert _close(want, got), (q, v, u, want, got)
        if mode != STUCK:  # the guards are the rolling mesh's (a stuck mesh waits for its release time)
            want_guards = stepping._guards(system, 0.0, q, v, u)
            got_guards = drive_guards(model, 0.0, *q, *v, u, direction)
            assert _close(want_guards, got_guards), (q, v, u, want_guards, got_guards)
        moving += any(x != 0.0 for x in want if math.isfinite(x))
    assert (moving == 0) == (mode == STUCK)  # stuck: q'' = 0; rolling: the law really acted


def _currents(scene, seed: int):
    """`_states` with a random winding current (A) over ±CURRENT i_max."""
    rng = np.random.default_rng(seed + 100)
    limit = scene.drive.current_limit
    for q, v, u, direction in _states(scene, seed):
        yield q, v, u, direction, float(rng.uniform(-CURRENT * limit, CURRENT * limit))


def _python_rates(system, t, q, v, u, i, mode):
    """(q'' rad/s², i' A/s) of the Python law; NaN for q'' where the back flank is not unique."""
    try:
        a = system.mesh(t, q, v, u, mode, i)[2]
    except SimulationDiverged:
        a = (math.nan,) * 3
    return (*a, system.drive.current_rate(u, i, v[0]))


@pytest.mark.parametrize("mode", [DRIVE, BACK, STUCK])
@pytest.mark.parametrize(("name", "scene"), INDUCTIVE, ids=[n for n, _ in INDUCTIVE])
def test_compiled_inductive_rates_and_guards_equal_python(name: str, scene, mode: int) -> None:
    system, model = _in_mode(scene, mode)
    drive = system.drive
    assert drive.inductive
    limited = 0
    for q, v, u, direction, i in _currents(scene, seed=mode + 7):
        drive.direction = direction
        want = _python_rates(system, 0.0, q, v, u, i, mode)
        got = inductive_rates(model, 0.0, *q, *v, u, i)
        assert _close(want[:3], got[:3]) and _close(want[3:], got[3:]), (q, v, u, i, want, got)
        if mode != STUCK:  # the rolling mesh's guards (the lean step breaks off on a stuck mesh)
            want_guards = inductive_stepping._guards(system, 0.0, q, v, i, u)
            got_guards = inductive_guards(model, 0.0, *q, *v, i, u, direction)
            assert _close(want_guards, got_guards), (q, v, u, i, want_guards, got_guards)
        limited += want[3] == 0.0  # the driver's limit held the current
    assert limited > 0  # the samples reach the limit's branch


@pytest.mark.parametrize("mode", [DRIVE, BACK, STUCK])
@pytest.mark.parametrize(("name", "scene"), INDUCTIVE, ids=[n for n, _ in INDUCTIVE])
def test_compiled_inductive_step_equals_python(name: str, scene, mode: int) -> None:
    system, _ = _in_mode(scene, mode)
    python = InductiveRungeKutta.of(METHODS["rk4"], SUBSTEPS)(system)
    compiled = CompiledInductiveRungeKutta.of(METHODS["rk4"], SUBSTEPS)(system)
    inputs = (scene.torque, lambda s: 7.0 * math.sin(900.0 * s))  # a profile (compiled), a function (Python)
    stepped = 0
    for k, (q, v, u, direction, i) in enumerate(_currents(scene, seed=mode + 11)):
        if k == STEP_SAMPLES:
            break
        system.drive.direction = direction
        t = k * DT
        for torque in inputs:
            outcome = []
            for integrator in (python, compiled):
                try:
                    q1, v1, (i1,) = integrator.advance_state(t, q, v, (i,), DT, torque, SUBSTEPS)
                    outcome.append((*q1, *v1, i1))
                except SimulationDiverged:  # a back flank that is not unique on the way: both must say so
                    outcome.append(None)
            want, got = outcome
            assert (want is None) == (got is None), (q, v, i, want, got)
            if want is not None:
                assert _close(want[:6], got[:6]) and _close(want[6:], got[6:]), (q, v, i, want, got)
                stepped += 1
    assert stepped > STEP_SAMPLES


@pytest.mark.parametrize("mode", [DRIVE, BACK])
@pytest.mark.parametrize(("name", "scene"), SCENES + INDUCTIVE, ids=[n for n, _ in SCENES + INDUCTIVE])
def test_compiled_mesh_solves_the_section8_law_and_is_passive(name: str, scene, mode: int) -> None:
    system, model = _in_mode(scene, mode)
    drive, p = system.drive, system.drive.params
    c = drive.c(mode)
    held = 0
    for q, v, u, direction, i in _currents(scene, seed=mode + 23):
        if not drive.inductive:
            i = drive.current(u, v[0])
            a = driven_accelerations(model, 0.0, *q, *v, u)
        else:
            a = inductive_rates(model, 0.0, *q, *v, u, i)[:3]
        if not all(math.isfinite(x) for x in a):  # a back flank that is not unique
            continue
        a0 = FingerSystem.accelerations(system, 0.0, q, v, 0.0)[0]
        m_eff = system.effective_inertia(q)
        tau_g = (a[0] - a0[0]) * m_eff  # θ1'' = a0 + τ_g / M_eff
        torque_only = FingerSystem.accelerations(system, 0.0, q, v, tau_g)[0]
        size = max(abs(x) for x in (*a, *a0))  # τ_g's round-off: a difference of accelerations this large
        assert max(abs(x - y) for x, y in zip(torque_only, a)) <= LAW * size, (q, v, u, i, torque_only, a)
        drive_side = p.gear_ratio * p.torque_constant * i
        reflected = p.gear_ratio**2 * p.rotor_inertia * a[0]
        scale = max(abs(c * tau_g), abs(reflected), abs(drive_side), abs(c * a0[0] * m_eff))  # τ_g's round-off
        assert abs(c * tau_g + reflected - drive_side) <= LAW * scale, (q, v, u, i)
        if direction * v[0] >= 0.0 and (direction if mode == DRIVE else -direction) * tau_g >= 0.0:  # the mode holds
            tau_a = p.torque_constant * i - p.rotor_inertia * p.gear_ratio * a[0]
            loss = tau_a * p.gear_ratio * v[0] - tau_g * v[0]
            assert loss >= -LAW * abs(tau_g * v[0]), (q, v, u, i, loss)
            held += 1
    assert held > 0  # the mode's conditions held at some samples
