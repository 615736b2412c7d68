"""Every registered effect (finger_sim.effects.EFFECTS) against the protocol's promises, on the
elements the shipped scenes build.

References: the element's own Python law against the compiled kernel's (the same Q to 1e-13 of its
size, at random states), central finite differences of the element's potential (Q(t, q, 0) = −∇V: at
rest every element is conservative; damping, friction and Hunt–Crossley damping vanish with q') and of
its gaps (∂gap/∂q). A new effect is checked here as soon as a scene below turns it on (the shipped
ones, and the paper's scene with gravity and a tip force, which no shipped scene uses); an effect that
none turns on fails `test_every_effect_is_checked`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from finger_sim import kinematics
from finger_sim.dynamics import FingerSystem
from finger_sim.effects import EFFECTS
from finger_sim.effects.base import NO_FORCE
from finger_sim.kernel import numerics
from finger_sim.kernel.force_laws import compiled_codes
from finger_sim.kernel.layout import model_array
from finger_sim.scene import load_scene, scene_from_dict

CONFIG = Path(__file__).resolve().parents[2] / "config"
SCENES = sorted([*CONFIG.glob("*.yaml"), *(CONFIG / "hard").glob("*.yaml")])
#: gravity (m/s²) and a tip force (N) of no shipped scene, turned on in the paper's scene
EXTRA_MODEL = {"gravity": [3.0, -9.81], "tip_force": [1.5, -2.0]}
SAMPLES = 400  # random states per element
AGREEMENT = 1e-13  # compiled vs Python Q, relative to the largest component
FD_STEP = 1e-6  # rad: central differences, truncation ~h² and round-off ~eps/h both far below FD_TOL
FD_TOL = 1e-6  # relative to the largest component (and 1 mN·m or 1 µm/rad absolute)
OFF_MANIFOLD = 0.05  # rad: states need not satisfy the loop closure for Q, V and the gaps
SPEED = 5.0  # rad/s: the range of random velocities


def _scenes() -> list[tuple[str, object]]:
    """(name, scene): the shipped scenes and the paper's scene with EXTRA_MODEL."""
    scenes = [(path.stem, load_scene(path)) for path in SCENES if path.name != "finger_node.yaml"]
    data = yaml.safe_load((CONFIG / "paper_flexion.yaml").read_text(encoding="utf-8"))
    data["model"] = {**(data.get("model") or {}), **EXTRA_MODEL}
    return [*scenes, ("paper_flexion_loaded", scene_from_dict(data))]


def _elements() -> dict[str, list]:
    """Effect key → (scene name, scene, element) of every scene that turns it on."""
    found: dict[str, list] = {key: [] for key in EFFECTS}
    for name, scene in _scenes():
        for key, eff in EFFECTS.items():
            element = eff.build(scene)
            if element is not None:
                found[key].append((name, scene, element))
    return found


ELEMENTS = _elements()
CASES = [pytest.param(key, scene, element, id=f"{key}-{name}")
         for key, cases in ELEMENTS.items() for name, scene, element in cases]


def _states(scene, seed: int) -> list[tuple[tuple[float, float, float], tuple[float, float, float]]]:
    """Assembled poses over the whole assembly range, pushed off the loop closure, with random rates."""
    rng = np.random.default_rng(seed)
    low, high = kinematics.assembly_range(scene.params)
    out = []
    for theta1 in rng.uniform(low, high, SAMPLES).tolist():
        q = np.array(kinematics.assemble(scene.params, theta1)) + rng.uniform(-OFF_MANIFOLD, OFF_MANIFOLD, 3)
        out.append((tuple(q.tolist()), tuple(rng.uniform(-SPEED, SPEED, 3).tolist())))
    return out


def _gradient(f, q: tuple[float, float, float]) -> np.ndarray:
    """Central differences of a scalar function of q."""
    grad = np.zeros(3)
    for i in range(3):
        up, down = list(q), list(q)
        up[i] += FD_STEP
        down[i] -= FD_STEP
        grad[i] = (f(tuple(up)) - f(tuple(down))) / (2.0 * FD_STEP)
    return grad


def test_every_effect_is_checked() -> None:
    """Every registered effect is turned on by a scene above, so the checks below cover it."""
    assert [key for key, cases in ELEMENTS.items() if not cases] == []


@pytest.mark.parametrize(("key", "scene", "element"), CASES)
def test_compiled_force_equals_python(key: str, scene, element) -> None:
    if getattr(element, "kernel_code", None) not in compiled_codes():
        pytest.skip(f"{key}: this element has no compiled form (the Simulator steps it in Python)")
    system = FingerSystem(scene.params, (element,))
    model = model_array(system)
    assert model is not None
    acting = 0
    for q, v in _states(scene, seed=1):
        want = element.force(0.0, q, v)
        got = numerics.generalized_force(model, 0.0, *q, *v, 0.0)
        size = max(abs(x) for x in want)
        assert max(abs(x - y) for x, y in zip(want, got)) <= AGREEMENT * size, (q, v, want, got)
        acting += size > 0.0
    assert acting > 0 or element.kernel_code == NO_FORCE  # the states really exercised the law


@pytest.mark.parametrize(("key", "scene", "element"), CASES)
def test_force_at_rest_is_minus_the_potential_gradient(key: str, scene, element) -> None:
    rest = (0.0, 0.0, 0.0)
    for q, _ in _states(scene, seed=2):
        force = np.array(element.force(0.0, q, rest))
        want = -_gradient(element.potential, q)
        scale = max(float(np.max(np.abs(force))), 1e-3)
        assert np.max(np.abs(force - want)) <= FD_TOL * scale, (q, force, want)


@pytest.mark.parametrize(("key", "scene", "element"), CASES)
def test_gap_gradients_are_the_gaps_derivatives(key: str, scene, element) -> None:
    checked = 0
    for q, _ in _states(scene, seed=3):
        gaps = element.gaps(q)
        for index in range(len(gaps)):
            got = np.array(element.gap_gradient(index, q))
            want = _gradient(lambda x: element.gaps(x)[index], q)
            scale = max(float(np.max(np.abs(got))), 1e-3)
            assert np.max(np.abs(got - want)) <= FD_TOL * scale, (q, index, got, want)
            checked += 1
    if element.smooth:
        assert checked == 0
    else:
        assert checked > 0
