"""The contact's candidate loop written once (`effects.contact_candidates.walk_candidates`): the kernel's
three walks (the force, the gaps, the gaps with rates and grip force) are that function compiled, and give
`Contact`'s own numbers bit for bit; the gaps agree with capsule distances computed here (numpy, a dense
sampling of each phalanx's axis) on shipped scenes with circles and planes."""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from finger_sim.effects import contact_candidates
from finger_sim.effects.contact import Contact
from finger_sim.effects.contact_geometry import Circle
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator

pytest.importorskip("numba")
from finger_sim.kernel import closed_loop, event_checks, numerics  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"
SCENES = ("grasp_cylinder", "press_table", "grasp_impact", "hard/friction_table", "hard/grasp_release")
#: Points sampled along a phalanx's axis (spacing ≈ 4e-8 m on a 4 cm phalanx).
SAMPLES = 1_000_001


def scene_contact(name: str) -> tuple[Simulator, Contact]:
    sim = Simulator(load_scene(CONFIG / f"{name}.yaml"), kernel="python")
    return sim, next(e for e in sim.system.elements if isinstance(e, Contact))


def contact_of(name: str) -> Contact:
    return scene_contact(name)[1]


def poses(name: str, rng: np.random.Generator) -> list[tuple[float, ...]]:
    """(θ1, θ2, θ3, θ1', θ2', θ3'): the scene's first 300 states, and each moved by up to ±0.05 rad and
    ±2 rad/s (the gaps need no closure), so that some are in contact and some not."""
    sim, _ = scene_contact(name)
    out = []
    for _ in range(300):
        state = sim.step()
        x = np.array((*state.q, *state.v))
        out += [tuple(x), tuple(x + rng.uniform(-1.0, 1.0, 6) * (0.05, 0.05, 0.05, 2.0, 2.0, 2.0))]
    return out


@pytest.mark.parametrize("walk", [numerics.contact_forces, event_checks._walk_gaps, closed_loop._walk_states])
def test_kernel_walks_are_the_one_loop(walk) -> None:
    assert walk.py_func.__code__ is contact_candidates.walk_candidates.__code__  # compiled, not copied


@pytest.mark.parametrize("name", SCENES)
def test_compiled_walks_give_the_elements_numbers_bit_for_bit(name: str) -> None:
    contact = contact_of(name)
    m = np.array(contact.kernel_params())
    count = len(contact.candidates())
    gaps, states, rates = np.empty(count), np.empty(count), np.empty(count)
    in_contact = 0
    for x in poses(name, np.random.default_rng(5)):
        q, v = x[:3], x[3:]
        assert event_checks.contact_gaps(m, 0, x[0], x[2], gaps) == count
        n, grip = closed_loop.contact_states(m, 0, np.array(x), states, rates)
        assert n == count
        assert tuple(gaps) == tuple(states) == contact.gaps(q)
        for i, rate in enumerate(rates):  # ∂gap/∂q · q', as the Simulator reads a rate
            g = contact.gap_gradient(i, q)
            assert rate == g[0] * v[0] + g[1] * v[1] + g[2] * v[2]
        assert grip == contact.outputs(0.0, q, v)["grip_force"]
        f1, f3 = numerics._contact(m, 0, x[0], x[2], v[0], v[2], False, 0.0, 0.0, 0.0, 0.0, 0.0)
        assert (f1, 0.0, f3) == contact.force(0.0, q, v)
        in_contact += min(contact.gaps(q)) < 0.0
    assert 3 <= in_contact <= 597  # in contact and out of it


def segment_distance(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    """Distance (m) from c to the segment a→b, by dense sampling."""
    points = a + np.linspace(0.0, 1.0, SAMPLES)[:, None] * (b - a)
    return float(np.hypot(*(points - c).T).min())


@pytest.mark.parametrize("name", SCENES)
def test_gaps_are_the_capsules_distances(name: str) -> None:
    """Per (phalanx, object): a circle's gap is the axis's distance to its centre − ρ − R; a plane's gaps are
    the heights of B (each phalanx) and of the tip (distal) above it − ρ; A is fixed and not a candidate."""
    contact = contact_of(name)
    r1, l3, alpha = contact.params.r1, contact.params.L3, contact.alpha
    rho = dict(zip(("proximal", "distal"), contact.radii))
    objects = {o.name: o for o in contact.objects}
    for x in poses(name, np.random.default_rng(7))[::100]:
        b = r1 * np.array([math.cos(x[0]), math.sin(x[0])])
        tip = b + l3 * np.array([math.cos(x[2] + alpha), math.sin(x[2] + alpha)])
        got = defaultdict(list)
        for (phalanx, obj), gap in zip(contact.candidates(), contact.gaps(x[:3])):
            got[phalanx, obj].append(gap)
        for (phalanx, obj_name), gaps in got.items():
            obj = objects[obj_name]
            start, end = (np.zeros(2), b) if phalanx == "proximal" else (b, tip)
            if isinstance(obj, Circle):
                want = [segment_distance(start, end, np.array(obj.center)) - rho[phalanx] - obj.radius]
            else:
                height = lambda p: float(np.dot(obj.normal, p - np.array(obj.point)))  # noqa: E731
                want = [height(b) - rho[phalanx]] + ([height(tip) - rho[phalanx]] if phalanx == "distal" else [])
            assert len(gaps) == len(want)
            np.testing.assert_allclose(sorted(gaps), sorted(want), rtol=0, atol=1e-7)
