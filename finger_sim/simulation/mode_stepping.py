"""Hybrid modes that their owner steps inside the Simulator's fixed step: one protocol the owner declares.

Like Drake's declared witness functions and updates: an owner of modes whose switches the Simulator's
own gap loop does not locate (the drive's mesh, spec §8; stick–slip friction, §7; an actuator in the
slot with its own slots) hands the Simulator a `ModeStepping`. It says how its modes start at t = 0
(`start`), how a smooth segment of a step is split at its events (`advance`, `after_step`), its continuous slots in
the flat state (`own_slots`), the lean compiled step it allows (`fast_stepper`), the method and
integrator it imposes (`auto_method`, `method_for`, `integrator_for`) and what it records of a whole run
(`record_run`, `run_states`). The Simulator, its set-up and `simulate` loop over what is declared and name
no owner; `simulation.mode_owners` lists the owners, one line each.

Two owners in one run: one `advance` steps the step, so one of them must step the other's modes too
(the friction cones and a stuck mesh lock as one, §7/§8). Each stepping declares what it carries (the
other steppings' `name`s, `carries`); the one that carries all the others leads (`leader`): its `start`
starts them and its `advance` steps them. Owners that no one carries together are refused in one line.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

from finger_sim.errors import ConfigError

if TYPE_CHECKING:
    import numpy as np

    from finger_sim.dynamics import FingerSystem
    from finger_sim.integrators import Integrator, TorqueFn
    from finger_sim.scene import Scene
    from finger_sim.simulation.driver import Simulator


class AutoPick(NamedTuple):
    """`method: auto`'s choice where a stepping leads: the method, its reason, the integrator's
    keyword options and the contact substeps."""

    method: str
    reason: str
    options: dict[str, float]
    substeps: int


class ModeStepping:
    """What an owner of hybrid modes declares to the Simulator; the defaults declare nothing.
    Subclasses set `name` (and `carries`) and write `advance`."""

    #: the stepping's name, as another's `carries` names it
    name: ClassVar[str]
    #: the other steppings whose modes (and events) this one's `start` and `advance` step too
    carries: ClassVar[tuple[str, ...]] = ()

    # -- the set-up (`simulation.setup`, kept per scene) -----------------------------------
    def auto_method(self, scene: Scene) -> AutoPick | None:
        """auto's method where this stepping leads; None: auto's table (`auto.choose_method`)."""
        return None

    def method_for(self, scene: Scene, method: str, reason: str, stable: Callable[[str], bool]) -> tuple[str, str]:
        """(method, reason) that can step its modes, from the one chosen (auto's or the scene's); a named
        one that cannot is refused (ConfigError). stable(name): whether that method is stable at auto's step."""
        return method, reason

    def integrator_for(self, scene: Scene, system: FingerSystem, method: type[Integrator],
                       integrator_cls: type[Integrator], kernel: str, gaps: bool) -> tuple[type[Integrator], str]:
        """The integrator class that steps its own slots with `method` (from the chosen `integrator_cls` on
        `kernel`), and what the method's reason adds; gaps: the scene has stops or contact."""
        return integrator_cls, ""

    # -- a run ---------------------------------------------------------------------------
    def start(self, sim: Simulator) -> None:
        """Its modes (and those it carries) at the scene's initial state; may set sim.v (a held start)."""

    def advance(self, sim: Simulator, t0: float, t1: float, u: TorqueFn) -> None:
        """Integrate [t0, t1] under a smooth input u(s), split at its events and the Simulator's gap events,
        its modes (and those it carries) switched on the way; sets sim.q, sim.v."""
        raise NotImplementedError

    #: called with the Simulator after each whole step of `Simulator.step`'s general path (a method of a
    #: subclass); None: nothing to do, and the Simulator makes no call
    after_step: Callable[[Simulator], None] | None = None

    def own_slots(self, sim: Simulator) -> tuple[float, ...]:
        """Its continuous slots at the current step (`state_layout`: after q, q' in owner order)."""
        return ()

    def fast_stepper(self, sim: Simulator) -> Any:
        """The lean compiled path of `Simulator.step` it allows (an object with `call`, `plan`, `profile`,
        `fail`), or None."""
        return None

    def before_run(self, sim: Simulator, n: int) -> None:
        """Before a whole run of n steps (`simulate`)."""

    def record_run(self, sim: Simulator, n: int, again: Callable[[], Simulator] | None,
                   ) -> tuple[np.ndarray, dict[str, np.ndarray], Mapping[str, float]] | None:
        """A whole run of n steps taken by this stepping, where its outputs are discrete state taken as the run
        goes: (the (n, 6) states, its outputs with the start's row first, its energy report); None: it
        records nothing of its own. again: a fresh Simulator of the same run (see `actuators.record.run`)."""
        return None

    def run_states(self, sim: Simulator, n: int) -> np.ndarray | None:
        """The (n, 6) states after each of n steps, where this stepping takes them faster than `Simulator.step`
        does one by one (same numbers); None: it does not."""
        return None


def leader(steppings: Sequence[ModeStepping]) -> ModeStepping | None:
    """The stepping whose `advance` steps every owner's modes: the one that carries all the others;
    None without steppings. ConfigError where none does (owners that cannot run together)."""
    if len(steppings) <= 1:
        return steppings[0] if steppings else None
    for candidate in steppings:
        if all(other is candidate or other.name in candidate.carries for other in steppings):
            return candidate
    names = " and ".join(s.name for s in steppings)
    raise ConfigError("model", "at most one owner of hybrid modes, or owners one of which carries the others",
                      names)
