"""A drive run's energy report made on its first read (`simulate`'s default) against the run that fills the
ledger as it goes (`energy_report=True`, the CLI's): the same states, outputs and error estimate bit for bit,
the same report bit for bit, and that report closes (spec §8's power balance: a conservation law)."""

from __future__ import annotations

import numpy as np
import pytest

import reference as ref
from finger_sim.scene import Scene, load_scene, scene_from_dict
from finger_sim.simulate import simulate
from test_stick_slip_drive import BACKDRIVABLE, data as stick_slip_data

CUP = {"name": "cup", "type": "circle", "center": [0.065, 0.040], "radius": 0.012}


def shipped(name: str) -> Scene:
    return load_scene(ref.CONFIG / f"{name}.yaml")


def free_square() -> Scene:
    """No gaps: the lean compiled step runs where the ledger is off; grasp and break-away at 0 V ↔ 4 V."""
    return scene_from_dict({"model": {"drive": {}, "spring_stiffness": 0.2},
                            "input": {"voltage": {"type": "square", "amplitude": 2.0, "offset": 2.0, "frequency": 10.0}},
                            "integrator": {"method": "rk6", "dt": 1e-3}, "duration": 0.3})


def inductive() -> Scene:
    """L > 0 on the cup: grasp, stuck hold, the current decaying after the drop."""
    return scene_from_dict({"model": {"drive": {"inductance": 1e-3}}, "objects": [CUP],
                            "input": {"voltage": {"type": "step", "before": 6.0, "after": 0.0, "at": 0.05}},
                            "integrator": {"dt": 1e-3}, "duration": 0.1})


def stick_slip() -> Scene:
    """The back-drivable drive sliding on a table under stick–slip friction (its own event loop):
    test_stick_slip_drive's scene."""
    return scene_from_dict(stick_slip_data({"friction": 0.3, "static_friction": 0.5}, {"type": "constant", "value": 0.0},
                                           0.2, BACKDRIVABLE, initial={"theta1": 0.286, "theta1_dot": 3.0}))


SCENES = {"drive_grasp": lambda: shipped("drive_grasp"),
          "drive_grasp_backdrivable": lambda: shipped("drive_grasp_backdrivable"),
          "free_square": free_square, "inductive": inductive, "stick_slip": stick_slip}


def bits(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a, dtype=np.float64).tobytes()


#: The inductive scene on the Python kernel takes 30 s (its 32 substeps per step in Python): compiled only.
CASES = [(name, kernel) for name in SCENES for kernel in ("compiled", "python") if (name, kernel) != ("inductive", "python")]


@pytest.mark.parametrize("name, kernel", CASES)
def test_the_report_made_on_read_equals_the_one_filled_during_the_run(name, kernel):
    if kernel == "compiled":
        pytest.importorskip("numba")
    scene = SCENES[name]()
    lazy, eager = simulate(scene, kernel=kernel), simulate(scene, kernel=kernel, energy_report=True)
    assert lazy.method == eager.method
    for a, b in [(lazy.t, eager.t), (lazy.q, eager.q), (lazy.v, eager.v), (lazy.energy, eager.energy)]:
        assert bits(a) == bits(b)
    assert list(lazy.outputs) == list(eager.outputs)
    assert all(bits(lazy.outputs[k]) == bits(eager.outputs[k]) for k in eager.outputs)
    assert bits(np.array([lazy.error_estimate])) == bits(np.array([eager.error_estimate]))
    assert dict(lazy.energy_report) == dict(eager.energy_report)
    report = eager.energy_report
    # the balance closes: electrical work = copper + mesh + ΔE_rotor + Δ(T + V) + dissipated (+ Δ½Li²)
    scale = max(abs(report["electrical_work"]), abs(report["dissipated"]), abs(report["linkage_energy_change"]))
    assert scale > 0.0 and abs(report["residual"]) <= 1e-3 * scale
    assert report["mesh_loss"] >= -1e-12


@pytest.mark.parametrize("name", ["drive_grasp", "drive_grasp_backdrivable"])
def test_the_kept_holding_torque_of_a_stuck_step_changes_no_bit(name):
    """A stuck step asks τ_h at its end twice (release test, outputs) and the next step once more at its start;
    kept (`DrivenSystem.keeps_holding_torque`) or evaluated each time, the run is the same bit for bit."""
    from finger_sim.actuators import record
    from finger_sim.simulate import Simulator

    scene = shipped(name)
    kept, fresh = Simulator(scene, kernel="python"), Simulator(scene, kernel="python")
    assert kept.system.keeps_holding_torque
    fresh.system.keeps_holding_torque = False
    (xs_a, rows_a), (xs_b, rows_b) = record.steps(kept, scene.step_count), record.steps(fresh, scene.step_count)
    assert bits(xs_a) == bits(xs_b) and bits(rows_a) == bits(rows_b)
    mode = list(kept.system.output_names()).index("mesh_mode")
    assert np.count_nonzero(rows_a[:, mode] == 2.0) > 100  # it held for most of the run (mesh_mode 2: stuck)
