"""The contact's design-force floor (`Contact.modal` at poses that press less than DESIGN_FORCE) follows
the objects' own stiffness and damping, not the scene's defaults that no object takes.

A cup that sets its own k_c = 1e3 under the scene's default k_c = 1e5 is the same physical scene as a
cup that takes k_c = 1e3 from the scene: the stability check must see the same contact mode in both.
The independent reference: the floor written here from its definition (spec §7's Hunt–Crossley
stiffness k e δ_d^(e−1) at F_d = k δ_d^e, times a² = (n_c·J_p n)² of the candidates from
hybrid_reference, n = ∂q/∂θ1 from reference.py).
"""

from __future__ import annotations

import pytest
import yaml

import reference as ref
from finger_sim import auto
from finger_sim.dynamics import FingerSystem
from finger_sim.effects.contact import DESIGN_FORCE, Contact
from finger_sim.scene import scene_from_dict
from finger_sim.stability import mcp_range
from hybrid_reference import _candidates

SOFT = 1e3  # N/m^e, a foam cup (config/tasks/hold_soft.yaml)
#: θ1 of an open pose, rad: the finger clear of the cup, where only the floor sizes the contact mode.
OPEN = 0.05


def cup_scene(own_stiffness: float | None, scene_stiffness: float) -> dict:
    """grasp_cylinder's cup, its k_c its own (`own_stiffness`) or the scene's."""
    d = yaml.safe_load((ref.CONFIG / "grasp_cylinder.yaml").read_text())
    d["model"]["contact"]["stiffness"] = scene_stiffness
    if own_stiffness is not None:
        d["objects"][0]["stiffness"] = own_stiffness
    return d


def contact_of(scene) -> Contact:
    return next(e for e in scene.build_system().elements if isinstance(e, Contact))


@pytest.mark.parametrize("own, default", [(SOFT, 1e5), (None, SOFT), (1e7, 1e5)])
def test_the_floor_is_the_stiffest_objects_own_law_at_the_design_force(own, default):
    """Out of contact the modal stiffness is k_d · max a² with k_d = k e (F_d/k)^((e−1)/e) of the cup's k_c."""
    d = cup_scene(own, default)
    contact = contact_of(scene_from_dict(d))
    q = ref.assemble(OPEN)
    n = ref.rates(q, 1.0)
    law = d["model"]["contact"]
    k, e = (default if own is None else own), law["exponent"]
    rho = tuple(d["model"]["phalanx_radius"])
    candidates = _candidates(q, d["objects"], rho)
    assert all(delta < 0.0 for delta, _, _ in candidates)  # open: the floor alone
    a2 = max(float(normal @ (jac @ n)) ** 2 for _, normal, jac in candidates)
    k_design = k * e * (DESIGN_FORCE / k) ** ((e - 1.0) / e)
    stiffness, _ = contact.modal(tuple(q), tuple(n))
    assert stiffness == pytest.approx(k_design * a2, rel=1e-9)


def test_a_cup_with_its_own_softness_has_the_contact_mode_of_the_same_cup_set_scene_wide():
    """The same foam cup written two ways gives auto the same contact mode and the same implicit substeps."""
    own, scene_wide = (scene_from_dict(cup_scene(*args)) for args in ((SOFT, 1e5), (None, SOFT)))
    omegas = [auto.contact_frequency(FingerSystem(s.params, [contact_of(s)]), mcp_range(s)) for s in (own, scene_wide)]
    assert omegas[0] == pytest.approx(omegas[1], rel=1e-12)
    assert auto.contact_substeps(own, implicit=True) == auto.contact_substeps(scene_wide, implicit=True)
