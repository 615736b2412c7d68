"""Wrenches and contact read from the declarations, not from a scene's objects.

- `effects.base.Wrench`: the contact effect declares its per-phalanx wrenches; every element of the scenes of
  test_declared_outputs reports exactly the declared wrenches whose force outputs it reports, their force
  those outputs' values and their moment Σ p × F of its contacts (`Contact.contacts`, about A); the registry
  refuses a wrench whose force is not among the effect's outputs, or split over two topics; finger_node's
  wrench topics are the declared ones (contact_wrench/<phalanx>, WrenchStamped, enabled by grip_force).
- "has contact" (auto's label and its event cost, stick–slip's own Simulator) is what the scene's elements
  declare: a new effect with kinks and no objects is contact to `auto`; a scene owns the friction mode only
  where its stick–slip contact is built (the old test on the scene's keys, written again here, agrees on every
  shipped scene).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from test_declared_outputs import SCENES
from test_effects import SoftStop

from finger_sim import auto, stick_slip
from finger_sim.effects import EFFECTS, Effect
from finger_sim.effects.base import Wrench, declared_wrenches, effect, has_kinks, reported_wrenches
from finger_sim.effects.contact_outputs import CONTACT_FORCES, CONTACT_WRENCHES, GRIP_FORCE
from finger_sim.scene import load_scene, scene_from_dict
from finger_sim.simulate import Simulator

CONFIG = Path(__file__).resolve().parents[2] / "config"
SHORT = ("drive_sensed", "pushed")  # 20 ms: over before the finger reaches the cup
FREE = {"model": {}, "input": {"torque": {"type": "constant", "value": 0.0}}, "duration": 0.01,
        "integrator": {"method": "auto", "dt": 0.001}}


def test_the_contact_effect_declares_a_wrench_on_each_phalanx() -> None:
    assert EFFECTS["contact"].wrenches == CONTACT_WRENCHES and declared_wrenches() == CONTACT_WRENCHES
    assert [(w.body, w.topic) for w in CONTACT_WRENCHES] == [("proximal", "contact_wrench/proximal"),
                                                             ("distal", "contact_wrench/distal")]
    assert all(w.force == CONTACT_FORCES[w.body] for w in CONTACT_WRENCHES)


def pressing(sim: Simulator) -> bool:
    """Whether an element reports a grip force at the Simulator's state."""
    return any(e.outputs(*sim.state).get(GRIP_FORCE.name, 0.0) > 0.0 for e in sim.system.elements)


@pytest.mark.parametrize("name", sorted(SCENES))
def test_every_element_reports_its_declared_wrenches(name: str) -> None:
    sim = Simulator(SCENES[name])
    while not pressing(sim) and sim.time < SCENES[name].duration:
        sim.step()
    t, q, v = sim.state
    pressed = 0
    for element in sim.system.elements:
        declared, wrenches = reported_wrenches(element, q), element.wrenches(t, q, v)
        assert len(declared) == len(wrenches)
        outputs = element.outputs(t, q, v)
        for wrench, (fx, fy, mz) in zip(declared, wrenches):
            x, y = wrench.force
            assert (fx, fy) == (outputs[x.name], outputs[y.name])
            mine = [c for c in element.contacts(t, q, v) if c.phalanx == wrench.body]  # type: ignore[attr-defined]
            assert mz == pytest.approx(sum(c.point[0] * c.force[1] - c.point[1] * c.force[0] for c in mine),
                                       rel=1e-12, abs=1e-18)
            pressed += bool(mine)
    assert (pressed > 0) == pressing(sim)
    assert pressing(sim) or name in SHORT


def test_the_registry_refuses_a_wrench_off_its_outputs_or_split_over_topics() -> None:
    proximal_x, _ = CONTACT_FORCES["proximal"]
    _, distal_y = CONTACT_FORCES["distal"]
    with pytest.raises(ValueError, match="one topic"):
        Wrench("proximal", (proximal_x, distal_y))
    with pytest.raises(ValueError, match="not among its outputs"):
        effect("pad", "a pad", outputs=(GRIP_FORCE,), wrenches=CONTACT_WRENCHES)(lambda scene: None)
    assert "pad" not in EFFECTS


def test_the_node_s_wrench_topics_are_the_declared_ones() -> None:
    pytest.importorskip("rclpy")
    from geometry_msgs.msg import WrenchStamped

    from finger_sim.ros.interfaces import OUTPUTS

    for wrench in declared_wrenches():
        spec = OUTPUTS[wrench.topic]
        assert (spec.topic, spec.msg_type, spec.reported_by) == (wrench.topic, WrenchStamped, GRIP_FORCE.name)
        assert wrench.force[0].message == "geometry_msgs/msg/WrenchStamped"


# -- "has contact" from the declarations ------------------------------------------------------
def test_a_new_effect_with_kinks_is_contact_to_auto(monkeypatch: pytest.MonkeyPatch) -> None:
    """No objects: before, auto called it a "stops" scene and left out the event loop's cost."""
    monkeypatch.setitem(EFFECTS, "soft_stop", Effect("soft_stop", lambda scene: SoftStop(True), "test kink"))
    scene = scene_from_dict(FREE)
    assert not scene.objects and scene.mcp_limits is None
    system = scene.build_system()
    assert [type(e) for e in system.elements if has_kinks(e, scene.initial_state()[0])] == [SoftStop]
    _, reason = auto.choose_method(scene)
    assert reason.startswith("contact scene (events of model.soft_stop")
    # the event loop's cost counts: at a dt whose budget holds one attempt but not one attempt and an event step
    dt = (auto.ATTEMPT_US + 0.5 * auto.EVENT_STEP_US) / (auto.REALTIME_SHARE * 1e6)
    fast = scene_from_dict({**FREE, "integrator": {"method": "auto", "dt": dt}})
    assert "cannot hold" in auto.realtime_note(fast, complex(-1.0, 0.0))
    monkeypatch.delitem(EFFECTS, "soft_stop")
    assert auto.realtime_note(fast, complex(-1.0, 0.0)) == ""


def _shipped() -> list[tuple[str, object]]:
    paths = [p for folder in (CONFIG, CONFIG / "friction", CONFIG / "hard") for p in sorted(folder.glob("*.yaml"))]
    return [(p.stem, load_scene(p)) for p in paths if p.name != "finger_node.yaml"]


@pytest.mark.parametrize(("name", "scene"), _shipped(), ids=[n for n, _ in _shipped()])
def test_the_friction_mode_is_owned_where_the_scene_asks_for_stick_slip(name: str, scene) -> None:
    law = getattr(scene, "friction_law", None)
    asked = bool(scene.objects) and law is not None and law.model == "stick_slip"  # the scene's keys, as before
    assert stick_slip.in_scene(scene) == asked
    assert (stick_slip.element(scene.build_system()) is not None) == asked
