"""The compiled kernel against the Python reference, and our DOP853 against a tight scipy solve."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from finger_sim import kinematics
from finger_sim.dynamics import FingerSystem
from finger_sim.effects.contact import Contact
from finger_sim.effects.contact_geometry import Circle, ContactParams, Plane
from finger_sim.errors import ConfigError, StabilityError
from finger_sim.integrators import METHODS
from finger_sim.kernel import PYTHON, compiled_name
from finger_sim.kernel.layout import CONTACT, model_array
from finger_sim.kinematics import distal_offset
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator, simulate

pytest.importorskip("numba")
from finger_sim.kernel import numerics  # noqa: E402  (needs numba to mean "compiled")
from finger_sim.kernel.integrators import compiled_twin  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"
SCENES = sorted(p for p in CONFIG.glob("*.yaml") if p.name != "finger_node.yaml")
FIXED_STEP = ("euler", "rk4", "rk6", "dop8")
#: A few hundred steps per scene keep the test fast; paper_to_stop runs whole (its stop
#: impact comes at step 426 of 600), and contact poses have their own test below.
STEPS = 250
WHOLE_RUNS = ("paper_to_stop",)
AGREEMENT = 1e-13  # rad, rad/s per unit state
#: A method unstable at a scene's dt runs at this fraction of its largest stable dt.
STABLE_FRACTION = 0.9
#: The step taken from each pose in contact, s: short enough for the stiffest contact shipped.
CONTACT_DT = 1e-6


@pytest.mark.parametrize("method", FIXED_STEP)
@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_compiled_and_python_agree(path: Path, method: str) -> None:
    scene = load_scene(path).with_overrides(method=method)
    try:
        python = Simulator(scene, kernel="python")
    except StabilityError as exc:  # a stiff scene: the explicit method needs a smaller step
        scene = scene.with_overrides(dt=STABLE_FRACTION * exc.safe_dt)
        python = Simulator(scene, kernel="python")
    compiled = Simulator(scene, kernel="compiled")
    assert python.kernel == PYTHON and compiled.kernel == compiled_name()
    steps = scene.step_count if path.stem in WHOLE_RUNS else min(STEPS, scene.step_count)
    for _ in range(steps):
        a, b = python.step(), compiled.step()
        scale = 1.0 + max(abs(x) for x in a.v)
        assert max(abs(x - y) for x, y in zip(a.q, b.q)) <= AGREEMENT
        assert max(abs(x - y) for x, y in zip(a.v, b.v)) <= AGREEMENT * scale
    assert python.impacts == compiled.impacts
    assert python.impacts > 0 or path.stem not in WHOLE_RUNS


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_whole_run_fast_path_equals_stepping(path: Path) -> None:
    """simulate()'s kernel loop gives the Simulator's step-by-step states bit for bit."""
    scene = load_scene(path)
    scene = scene.with_overrides(duration=min(scene.duration, 0.2))
    kernel = Simulator(scene).kernel  # compiled where the method has a compiled form
    run = simulate(scene, kernel=kernel)
    sim = Simulator(scene, kernel=kernel)
    states = [sim.step() for _ in range(scene.step_count)]
    assert np.array_equal(run.q[1:], np.array([s.q for s in states]))
    assert np.array_equal(run.v[1:], np.array([s.v for s in states]))


def test_compiled_contact_force_equals_python() -> None:
    """Hunt–Crossley + friction on circles and planes: the compiled Q equals the element's."""
    base = load_scene(CONFIG / "paper_flexion.yaml")
    params = base.params
    objects = (Circle("can", (0.035, 0.045), 0.02), Circle("peg", (0.01, 0.03), 0.006),
               Plane("table", (0.0, 0.06), (0.2, -1.0)), Plane("wall", (0.07, 0.0), (-1.0, 0.1)))
    law = ContactParams(stiffness=2e5, exponent=1.5, damping=1.2, friction=0.6, slip_velocity=2e-3)
    contact = Contact(params, distal_offset(params), contact=law, objects=objects)
    system = FingerSystem(params, (*base.force_elements(), contact))
    model = model_array(system)
    assert model is not None
    rng = np.random.default_rng(7)
    touching = 0
    for _ in range(2000):
        q = tuple(rng.uniform(-0.3, 1.9, 3).tolist())
        v = tuple(rng.uniform(-20.0, 20.0, 3).tolist())
        want = system.generalized_force(0.1, q, v, 0.002)
        got = numerics.generalized_force(model, 0.1, *q, *v, 0.002)
        size = max(abs(x) for x in want)
        assert max(abs(x - y) for x, y in zip(want, got)) <= 1e-13 * size
        touching += contact.force(0.1, q, v) != (0.0, 0.0, 0.0)
    assert touching > 100  # the poses really pressed on the objects


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_compiled_step_agrees_in_contact(path: Path) -> None:
    """One step of every fixed-step method from poses pressing on the scene's objects."""
    scene = load_scene(path)
    system = scene.build_system()
    contact = [e for e in system.elements if e.kernel_code == CONTACT]
    if not contact:
        pytest.skip(f"{path.stem} has no objects")
    rng = np.random.default_rng(3)
    low, high = kinematics.assembly_range(scene.params)
    poses = []
    for theta1 in np.linspace(low, high, 400)[1:-1].tolist():
        q = kinematics.assemble(scene.params, theta1)
        v = kinematics.dependent_rates(scene.params, q, float(rng.uniform(-5.0, 5.0)))
        if contact[0].force(0.0, q, v) != (0.0, 0.0, 0.0):
            poses.append((q, v))
    assert poses, "no pose of the sweep touches an object"
    for method in FIXED_STEP:
        python, compiled = METHODS[method](system), compiled_twin(METHODS[method])(system)
        for q, v in poses:
            a, b = python.step(0.05, q, v, CONTACT_DT, scene.torque), compiled.step(0.05, q, v, CONTACT_DT, scene.torque)
            scale = 1.0 + max(abs(x) for x in a[1])
            assert max(abs(x - y) for x, y in zip(a[0], b[0])) <= AGREEMENT
            assert max(abs(x - y) for x, y in zip(a[1], b[1])) <= AGREEMENT * scale


def test_dop853_matches_a_tight_reference() -> None:
    scene = load_scene(CONFIG / "paper_flexion.yaml").with_overrides(method="dop853")
    system = scene.build_system()
    q0, v0 = scene.initial_state()
    grid = np.arange(scene.step_count + 1) * scene.dt
    ref = solve_ivp(lambda s, y: system.rhs(s, y, scene.torque), (0.0, grid[-1]), [*q0, *v0], method="DOP853",
                    rtol=1e-13, atol=1e-15, t_eval=grid)
    run = simulate(scene)
    assert run.method == "dop853"
    assert np.abs(run.q - ref.y[:3].T).max() <= 2e-9
    assert run.residual.max() <= 1e-14  # projected at every output


def test_unknown_kernel_is_refused() -> None:
    with pytest.raises(ConfigError, match="kernel"):
        Simulator(load_scene(CONFIG / "paper_flexion.yaml"), kernel="fortran")


def test_compiled_is_refused_for_a_method_without_compiled_form() -> None:
    scene = load_scene(CONFIG / "paper_flexion.yaml").with_overrides(method="rattle")
    assert Simulator(scene).kernel == PYTHON
    with pytest.raises(ConfigError, match="rattle"):
        Simulator(scene, kernel="compiled")


def test_projection_status_matches_python() -> None:
    from finger_sim.projection import project

    system = load_scene(CONFIG / "paper_flexion.yaml").build_system()
    model = model_array(system)
    x = np.array([0.31, 0.9, -0.7, 1.0, -2.0, 3.0])
    want = project(system.params, tuple(x[:3]), tuple(x[3:]))
    assert numerics.project(model, x) == numerics.OK
    assert x.tolist() == [*want[0], *want[1]]
    bad = np.array([math.nan, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert numerics.project(model, bad) == numerics.NON_FINITE


def test_without_numba_the_python_path_runs(tmp_path: Path) -> None:
    """numba missing: "auto" steps in Python, dop853 runs its numerics as plain Python."""
    code = (
        "import sys; sys.modules['numba'] = None\n"
        "from finger_sim.scene import load_scene\n"
        "from finger_sim.simulate import Simulator, simulate\n"
        f"scene = load_scene({str(CONFIG / 'paper_flexion.yaml')!r}).with_overrides(duration=0.01)\n"
        "print(Simulator(scene).kernel, simulate(scene.with_overrides(method='dop853')).q[-1, 0])\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path)
    kernel, theta1 = out.stdout.split()
    assert kernel == PYTHON
    reference = simulate(load_scene(CONFIG / "paper_flexion.yaml").with_overrides(duration=0.01, method="dop853"))
    assert abs(float(theta1) - reference.q[-1, 0]) <= 1e-13


PROFILES = {
    "constant": {"type": "constant", "value": 0.004},
    "ramp": {"type": "ramp", "offset": 0.001, "slope": 0.01},
    "sine": {"type": "sine", "amplitude": 0.003, "frequency": 7.0, "offset": 0.001},
    # switches inside a step (0.1234 s, and every 1/(2·9.7) s), and one on a step's end (0.05 s)
    "step": {"type": "step", "before": 0.0, "after": 0.005, "at": 0.1234},
    "square": {"type": "square", "amplitude": 0.004, "frequency": 9.7},
    "step_on_grid": {"type": "step", "before": 0.002, "after": -0.001, "at": 0.05},
}


@pytest.mark.parametrize("method", ("euler", "rk6"))
@pytest.mark.parametrize("name", sorted(PROFILES))
def test_compiled_profiles_agree_with_python(name: str, method: str) -> None:
    """Simulator.step's compiled path (τ evaluated in the kernel) against the Python path."""
    from finger_sim.inputs import profile_from_dict

    scene = load_scene(CONFIG / "paper_flexion.yaml").with_overrides(method=method, duration=0.2)
    scene = dataclasses.replace(scene, torque=profile_from_dict(PROFILES[name]))
    python, compiled = Simulator(scene, kernel="python"), Simulator(scene, kernel="compiled")
    assert compiled.fast_stepper is not None and compiled.fast_stepper.profile is not None
    for _ in range(scene.step_count):
        a, b = python.step(), compiled.step()
        assert a.t == b.t and python.torque == compiled.torque
        assert max(abs(x - y) for x, y in zip((*a.q, *a.v), (*b.q, *b.v))) <= AGREEMENT * (1.0 + max(map(abs, a.v)))
    run = simulate(scene, kernel="compiled")  # the whole-run loop, with its switches split in Python
    assert np.abs(run.q[-1] - np.array(python.q)).max() <= AGREEMENT


def test_held_torque_on_the_compiled_path_agrees_with_python() -> None:
    """The node's path: a held command per step (changing now and then), both kernels."""
    scene = load_scene(CONFIG / "paper_flexion.yaml")
    python, compiled = Simulator(scene, kernel="python"), Simulator(scene, kernel="compiled")
    for n in range(300):
        held = 0.002 + 0.001 * (n // 40)
        a, b = python.step(held), compiled.step(held)
        assert compiled.torque == held
        assert max(abs(x - y) for x, y in zip((*a.q, *a.v), (*b.q, *b.v))) <= AGREEMENT * (1.0 + max(map(abs, a.v)))


def test_compiled_torque_and_switches_equal_the_profiles() -> None:
    """numerics.torque_at equals each profile's __call__ bit for bit; switches_inside its breakpoints."""
    from finger_sim.inputs import profile_array, profile_from_dict
    from finger_sim.simulate import BREAK_EPS

    times = np.random.default_rng(5).uniform(0.0, 2.0, 2000).tolist()
    dt = 1e-3
    for data in PROFILES.values():
        profile = profile_from_dict(data)
        prof = profile_array(profile)
        assert all(numerics.torque_at(prof, 0.0, t) == profile(t) for t in times)
        for k in range(0, 400):
            t0, t1 = k * dt, (k + 1) * dt
            eps = BREAK_EPS * dt
            want = any(t0 + eps < b < t1 - eps for b in profile.breakpoints(t0, t1))
            assert numerics.switches_inside(prof, t0, t1, eps) == want


def test_a_compiled_kernel_log_resims_bit_for_bit() -> None:
    """Item 1: the log names its kernel, and resim steps with that one (bit for bit)."""
    from finger_sim.joints import joint_positions, joint_velocities
    from finger_sim.run_log import CommandEvent, RecordedRun, RunMetadata, resimulate, run_metadata, stamp_ns

    scene = load_scene(CONFIG / "paper_flexion.yaml")
    sim = Simulator(scene, kernel="compiled")
    record = run_metadata(scene, method=sim.method, method_reason="", torque_source="topic", parameters={},
                          kernel=sim.kernel)
    meta = RunMetadata.from_dict(record)
    assert meta.kernel == sim.kernel == compiled_name()
    q_ext, alpha = kinematics.extended_pose(scene.params), kinematics.distal_offset(scene.params)
    states, events, held = [], [], 0.0
    for n in range(scene.step_count + 1):  # what the node records: the state, then the step under the command
        states.append((stamp_ns(0, n, scene.dt), joint_positions(sim.q, q_ext, alpha) + joint_velocities(sim.v)))
        if n % 50 == 0:
            held = 0.001 * (1 + n // 50)
            events.append(CommandEvent("accepted", step=n, episode=0, stamp_ns=stamp_ns(0, n, scene.dt), torque=held))
        sim.step(held)
    result = resimulate(RecordedRun(meta, joint_states=states, events=events))
    assert result.exact and result.compared == scene.step_count + 1
    old = {k: v for k, v in record.items() if k != "kernel"}  # a log made before the key existed
    assert RunMetadata.from_dict(old).kernel == PYTHON
    with pytest.raises(ConfigError, match="kernel"):
        foreign = RunMetadata.from_dict({**record, "kernel": "fortran"})
        resimulate(RecordedRun(foreign, joint_states=states, events=events))
