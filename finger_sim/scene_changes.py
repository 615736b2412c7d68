"""Scene changes at step boundaries: a tip-force profile and crushed objects, for a run stepped step by step.

Two things change a scene while it runs, both at step boundaries and both by handing the state
to a Simulator of the changed scene (`grasp_objects.carry_over`):

- the tip-force profile (scene key `input.tip_force`, finger_sim.tip_force_profile): the force of
  the span in force from each switch step on;
- crushing (`grasp_objects.crush_step`): an object whose break_force the step exceeded is taken out.

`SceneChanges` applies both, in this order around every step: the tip force in force at step k,
the step, the crush check. finger_node, `finger-sim tasks` and `resim` step scenes through it, so
the three give the same states bit for bit. A drive scene refuses both for now: the new Simulator
would start the drive's mesh mode afresh (spec §8) instead of carrying it over.
"""

from __future__ import annotations

from finger_sim.errors import ConfigError
from finger_sim.grasp_objects import Crush, breakable, carry_over, crush_step, with_tip_force
from finger_sim.scene import Scene
from finger_sim.simulate import Simulator, State
from finger_sim.tip_force_profile import static_scene, tip_force_switches


class SceneChanges:
    """A scene stepped with its changes: the tip-force profile and crushing (module docstring).

    `sim` is the Simulator to step next: after a change a new one, of the changed scene, in the
    same state. `crushes` are this episode's; `before` is the Simulator as it ended the last step
    when that step crushed something (its contact element still holds the broken object), else None.
    """

    def __init__(self, scene: Scene, *, kernel: str = "auto", sim: Simulator | None = None) -> None:
        """`sim`: a Simulator of `static_scene(scene)` already made (else one is made here)."""
        self.scene = scene
        self.switches = tip_force_switches(scene)
        if scene.drive is not None and (self.switches or breakable(scene)):
            raise ConfigError("model.drive", "no tip-force profile (input.tip_force, a task's disturbances) and no "
                              "break_force with a drive yet: a scene change would not carry its mesh mode over",
                              scene.name)
        self.initial = sim if sim is not None else Simulator(static_scene(scene), kernel=kernel)
        self.sim = self.initial
        self.watching = breakable(scene)
        self.crushes: list[Crush] = []
        self.before: Simulator | None = None
        self._reported = 0  # crushes already taken by `new`

    def before_step(self) -> None:
        """The tip force in force over the next step (a switch at this step: a new Simulator)."""
        force = self.switches.get(self.sim.step_index)
        if force is not None and self.sim.step_index > 0:  # step 0's force is static_scene's
            self.sim = carry_over(self.sim, with_tip_force(self.sim.scene, force))

    def after_step(self) -> list[Crush]:
        """Check the step just taken; a crushed object is taken out of the scene. The new crushes."""
        self.before = None
        if not self.watching:
            return []
        sim, broken = crush_step(self.sim)
        if broken:
            self.before, self.sim = self.sim, sim
            self.crushes += broken
            self.watching = breakable(sim.scene)
        return broken

    def step(self, torque: float | None = None) -> State:
        """before_step, one step of `sim` with `torque`, after_step; the state after the step."""
        self.before_step()
        state = self.sim.step(torque)
        self.after_step()
        return state

    def new(self) -> list[Crush]:
        """The crushes since the last call (each reported once)."""
        fresh = self.crushes[self._reported:]
        self._reported = len(self.crushes)
        return fresh

    def reset(self) -> None:
        """The scene at its start again: every object, the tip force of step 0, the initial state."""
        self.initial.reset()
        self.sim, self.before = self.initial, None
        self.crushes = []
        self._reported = 0
        self.watching = breakable(self.scene)
