"""Slow corners (issue 17 item 5): a Simulator of a scene seen before reuses its set-up, importing
the simulator does not import scipy.integrate, and the install step leaves numba's cache warm.

Speed itself is measured in docs/sweep_performance.md; these tests check the mechanisms, with
numbers held against an uncached run.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

import pytest

from finger_sim.depth_guard import DepthLimit
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator, simulate
from finger_sim.simulation.setup import setup_for

CONFIG = Path(__file__).resolve().parents[2] / "config"
TOLERANCE = 1e-12  # rad


def _python(code: str) -> str:
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=240, check=True)
    return done.stdout.strip()


def test_a_scene_seen_before_shares_its_set_up_but_not_its_state():
    scene = load_scene(CONFIG / "paper_flexion.yaml")
    first, second = Simulator(scene), Simulator(scene)
    assert first.system is second.system and first.fast_stepper is second.fast_stepper
    for _ in range(150):
        first.step()
    assert second.step_index == 0 and second.q == scene.initial_state()[0]
    for _ in range(150):
        second.step()
    assert second.q == first.q and second.v == first.v
    reference = simulate(scene, kernel="python")  # the readable path, no compiled set-up shared
    np.testing.assert_allclose(first.q, reference.q[150], rtol=0, atol=TOLERANCE)


def _own_elements(sim: Simulator) -> bool:
    """Whether every gap of `sim` is on its own system's elements (a depth gap: on its contact)."""
    return all(any((g.element.contact if isinstance(g.element, DepthLimit) else g.element) is e
                   for e in sim.system.elements) for g in sim._gaps)


@pytest.mark.parametrize("name", ["friction/hold_table", "friction/pushed_table", "drive_grasp"])
def test_a_scene_whose_system_holds_run_state_shares_the_set_up_but_builds_its_own_system(name):
    # a friction mode, a drive's mesh mode: state of the system, so each Simulator needs its own; the
    # start's findings (the holding test, the mesh's rule at the initial state) are kept with the set-up
    scene = load_scene(CONFIG / f"{name}.yaml")
    steps = 300
    setup_for.cache_clear()
    uncached = Simulator(scene)  # its set-up computed for it
    start_modes = uncached.modes
    for _ in range(steps):
        uncached.step()
    assert uncached.modes != start_modes  # the run changes a mode: the state that must not be shared
    first, second = Simulator(scene), Simulator(scene)  # both from the kept set-up
    assert setup_for.cache_info().hits >= 2
    assert first.system is not second.system and first.system is not uncached.system
    assert _own_elements(first) and _own_elements(second) and len(first._gaps) == len(uncached._gaps) > 0
    assert first._integrator_cls is second._integrator_cls and first.method == uncached.method
    assert first.kept_start is second.kept_start is uncached.kept_start and uncached.kept_start
    for _ in range(steps):
        first.step()
    assert second.step_index == 0 and second.q == scene.initial_state()[0] and second.modes == start_modes
    for _ in range(steps):
        second.step()
    assert (first.q, first.v, first.modes) == (second.q, second.v, second.modes) == (uncached.q, uncached.v, uncached.modes)


def test_importing_the_simulator_leaves_scipy_integrate_until_a_method_needs_it():
    out = _python(
        "import sys\n"
        "import finger_sim.simulate as s\n"
        "from finger_sim.scene import load_scene\n"
        f"scene = load_scene({str(CONFIG / 'paper_flexion.yaml')!r})\n"
        "print('scipy.integrate' in sys.modules)\n"
        "s.simulate(scene.with_overrides(method='dop853', duration=0.01))\n"
        "print('scipy.integrate' in sys.modules)\n"
        "s.simulate(scene.with_overrides(method='adaptive', duration=0.002))\n"
        "print('scipy.integrate' in sys.modules)\n")
    assert out.split() == ["False", "False", "True"]


def test_the_install_step_leaves_every_kernel_compiled_in_the_cache():
    # make's install step runs finger_sim.kernel.warm; running it again must compile nothing
    out = _python(
        "from numba.core.registry import CPUDispatcher\n"
        "from finger_sim.kernel.warm import warm\n"
        "warm()\n"
        # a user's first inductive stick–slip run (issue 22): the warm must have compiled its step
        "import yaml\n"
        "from finger_sim.scene import scene_from_dict\n"
        "from finger_sim.simulate import simulate\n"
        f"d = yaml.safe_load(open({str(CONFIG / 'friction' / 'hold_table.yaml')!r}))\n"
        "d['model']['drive'] = {'inductance': 0.05}\n"
        "d['input'] = {'voltage': {'type': 'step', 'before': 3.0, 'after': 0.0, 'at': 0.005}}\n"
        "d['duration'] = 0.01\n"
        "simulate(scene_from_dict(d), kernel='compiled')\n"
        "from finger_sim.kernel import closed_loop, drive, event_checks, event_run, numerics, rollout_loop\n"
        "hits = misses = 0\n"
        "for module in (numerics, rollout_loop, event_checks, closed_loop, drive, event_run):\n"
        "    for f in vars(module).values():\n"
        "        if isinstance(f, CPUDispatcher):\n"
        "            hits += sum(f.stats.cache_hits.values())\n"
        "            misses += sum(f.stats.cache_misses.values())\n"
        "print(hits, misses)\n")
    hits, misses = map(int, out.split())
    assert hits >= 8 and misses == 0
