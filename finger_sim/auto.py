"""`method: auto`: pick the integrator from the scene's active effects and its dt."""

from __future__ import annotations

from finger_sim import kinematics
from finger_sim.integrators import METHODS
from finger_sim.scene import Scene
from finger_sim.stability import fastest_mode, stable_at


def choose_method(scene: Scene) -> tuple[str, str]:
    """(method, reason) for `method: auto`: the cheapest method that is stable and accurate at dt."""
    system = scene.build_system()
    root = fastest_mode(system, scene.mcp_limits or kinematics.assembly_range(scene.params))
    if stable_at(METHODS["rk4"], root, scene.dt):
        return "rk4", f"smooth scene, fastest mode |s|·dt = {abs(root) * scene.dt:.3g} inside RK4's stability region"
    return "radau", f"stiff scene: fastest mode |s|·dt = {abs(root) * scene.dt:.3g} is outside RK4's stability region"
