"""`finger-sim view` in a real browser: Debian's Chromium, headless, driven by Playwright through
its executable path, with every request but the file itself aborted and no console error allowed.

References, independent of the viewer: the node's log read by mcap + mcap_ros2 (not finger_sim's
reader), mapped to the model plane by spec §1/§6 written out here (θ_ext solved by scipy from
the spec's rounded values); for the screenshots, reference images in test/view/view_reference/
(regenerate with FINGER_SIM_UPDATE_VIEW_REFERENCES=1 after a deliberate change of the drawing).
Screenshots are kept in out/view_screenshots/ for a person to look at.

Without /usr/bin/chromium the module is skipped, except on CI (CI=true), where it fails:
.ci/run installs the browser.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from scipy.optimize import fsolve

from conftest import Launcher, allocate_domain_id, ros_environment

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config"
CHROMIUM = Path("/usr/bin/chromium")
#: Chromium without a first-run, sync, update or any background traffic; no GPU in CI.
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
                 "--no-first-run", "--disable-sync", "--disable-extensions", "--disable-default-apps"]
VIEWPORT = {"width": 1280, "height": 900}
LOAD_TIMEOUT_MS = 30_000
NODE_TIMEOUT_S = 90.0
REFERENCES = Path(__file__).with_name("view_reference")
SCREENSHOTS = ROOT / "out" / "view_screenshots"
UPDATE_REFERENCES = os.environ.get("FINGER_SIM_UPDATE_VIEW_REFERENCES") == "1"
#: Reference images are compared (and stored) as grey levels at this size, px.
REFERENCE_SIZE = (220, 165)
#: Mean |difference| of grey levels (0-255) a screenshot may show against its reference
#: (font hinting, anti-aliasing of another Chromium build); a moved link changes it by > 3.
SCREENSHOT_TOLERANCE = 1.5
POSITION_TOL = 2e-9  # m: the page holds positions to 1e-9 m
# Spec §1, Table II (m, rad) and the rounded extended pose it prints (deg).
R1, R2, R3, R4, L3 = 0.046, 0.0444, 0.0077, 0.0085, 0.0425
THETA4 = math.pi - 0.49
THETA_EXT_DEG = (13.1028, -128.0309)
SCENES = sorted(p.stem for p in CONFIG.glob("*.yaml") if p.stem != "finger_node")
#: Longest stretch of a shipped scene the screenshot test simulates, s (finger_default runs an hour).
SCREENSHOT_DURATION_S = 0.6


# -- the browser -----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """Headless Chromium for the module, closed even when a test fails."""
    if not CHROMIUM.exists():
        if os.environ.get("CI", "").lower() in ("true", "1", "yes"):
            pytest.fail(f"CI: {CHROMIUM} is missing; .ci/run installs Debian's chromium")
        pytest.skip(f"Debian's Chromium is not installed ({CHROMIUM}; apt-get install chromium)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        chromium = playwright.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
        try:
            yield chromium
        finally:
            chromium.close()


@contextmanager
def opened(browser: Any, path: Path) -> Iterator[Any]:
    """The viewer at `path` in a new page; on leaving: no request but the file, no console error."""
    uri = path.resolve().as_uri()
    page = browser.new_page(viewport=VIEWPORT)
    errors: list[str] = []
    requests: list[str] = []
    page.on("console", lambda message: errors.append(message.text) if message.type == "error" else None)
    page.on("pageerror", lambda error: errors.append(str(error)))

    def route(r: Any) -> None:
        requests.append(r.request.url)
        r.continue_() if r.request.url == uri else r.abort()

    page.route("**/*", route)
    try:
        page.goto(uri)
        page.wait_for_selector("body[data-ready=true]", state="attached", timeout=LOAD_TIMEOUT_MS)
        yield page
        assert requests == [uri], f"the page asked for more than itself: {requests}"
        assert errors == [], errors
    finally:
        page.close()


def show_time(page: Any, t: float) -> int:
    """Move the slider as a user does (value + input event) to the last frame at or before t."""
    k = page.evaluate("t => window.fingerView.frameAt(t + 5e-10)", t)
    page.evaluate("k => { const s = document.getElementById('slider'); s.value = k; "
                  "s.dispatchEvent(new Event('input', {bubbles: true})); }", k)
    return k


def drawn(page: Any, finger: str) -> tuple[float, dict[str, tuple[float, float]]]:
    """(the frame's time, point → drawn (x, y) in m) of one finger, read from the SVG's data."""
    t = float(page.get_attribute(f"g.finger[data-finger='{finger}']", "data-t"))
    points = page.eval_on_selector_all(f"g.finger[data-finger='{finger}'] circle[data-point]",
                                       "els => els.map(e => [e.dataset.point, Number(e.dataset.x), Number(e.dataset.y)])")
    return t, {name: (x, y) for name, x, y in points}


# -- the independent reference ---------------------------------------------------------------------


def extended_pose() -> tuple[float, float]:
    """(θ2_ext, θ3_ext), rad: the loop closure at θ1 = 0 solved tightly from the spec's rounded values."""
    def closure(x: np.ndarray) -> list[float]:
        t2, t3 = x
        return [R1 + R4 * math.cos(THETA4) - R2 * math.cos(t2) - R3 * math.cos(t3),
                R4 * math.sin(THETA4) - R2 * math.sin(t2) - R3 * math.sin(t3)]

    t2, t3 = fsolve(closure, np.radians(THETA_EXT_DEG), xtol=1e-13)
    return float(t2), float(t3)


def spec_points(mcp: float, coupler: float, pip: float) -> dict[str, tuple[float, float]]:
    """Spec §6 joint positions → spec §1 points in the model plane, m."""
    t2_ext, t3_ext = extended_pose()
    alpha = -t3_ext  # α = θ1_ext − θ3_ext, θ1_ext = 0
    t1, t2 = mcp, coupler + t2_ext
    t3 = pip + t1 - alpha
    d = (-R4 * math.cos(THETA4), -R4 * math.sin(THETA4))
    b = (R1 * math.cos(t1), R1 * math.sin(t1))
    return {"A": (0.0, 0.0), "B": b, "D": d, "C": (d[0] + R2 * math.cos(t2), d[1] + R2 * math.sin(t2)),
            "tip": (b[0] + L3 * math.cos(t3 + alpha), b[1] + L3 * math.sin(t3 + alpha))}


def read_log(path: Path) -> dict[str, dict[int, Any]]:
    """topic → log time (ns) → decoded message, by mcap + mcap_ros2."""
    out: dict[str, dict[int, Any]] = {}
    with path.open("rb") as file:
        for _, channel, message, decoded in make_reader(file, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            out.setdefault(channel.topic, {})[message.log_time] = decoded
    return out


def joints(state: Any) -> tuple[float, float, float]:
    """(mcp, coupler, pip) positions of a JointState, by name (a hand's carry a frame prefix)."""
    names = list(state.name)
    return tuple(state.position[next(i for i, n in enumerate(names) if n.endswith(j))]  # type: ignore[return-value]
                 for j in ("mcp_joint", "coupler_joint", "pip_joint"))


def assert_drawn_state(page: Any, finger: str, states: dict[int, Any]) -> int:
    """The finger's drawn points equal its logged joint state at the drawn time; that stamp, ns."""
    t, points = drawn(page, finger)
    stamp = round(t * 1e9)
    expected = spec_points(*joints(states[stamp]))
    for name, (x, y) in expected.items():
        assert math.hypot(points[name][0] - x, points[name][1] - y) < POSITION_TOL, (finger, t, name, points[name], (x, y))
    return stamp


# -- logs and views --------------------------------------------------------------------------------


def run_node(tmp: Path, module: str, params: dict[str, Any]) -> Path:
    """Run a node (scene torque, as fast as possible) to its end; its log."""
    pytest.importorskip("rclpy")
    launcher = Launcher(ros_environment(allocate_domain_id()), tmp)
    try:
        node = launcher.node(module, dict(torque_source="scene", realtime_factor=0.0, record_dir=str(tmp / "bags"),
                                          marker_rate_hz=0.0, **params))
        assert node.wait(NODE_TIMEOUT_S) == 0, node.output()
    finally:
        launcher.stop_all()
    (path,) = sorted((tmp / "bags").glob("*.mcap"))
    return path


@pytest.fixture(scope="module")
def grasp_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """grasp_cylinder through finger_node: a log with grip_force and contact wrenches."""
    return run_node(tmp_path_factory.mktemp("grasp"), "finger_sim.ros.node", {"scene": str(CONFIG / "grasp_cylinder.yaml")})


@pytest.fixture(scope="module")
def hand_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """finger_hand with two fingers of different scenes at different base poses."""
    tmp = tmp_path_factory.mktemp("hand")
    hand = tmp / "two_fingers.yaml"
    hand.write_text("fingers:\n"
                    f"  - {{name: index, scene: {CONFIG / 'grasp_cylinder.yaml'}, pose: [0.0, 0.022, 0.0, 0.0, 0.0, 0.0]}}\n"
                    f"  - {{name: middle, scene: {CONFIG / 'paper_flexion.yaml'}, pose: [0.004, 0.0, 0.0, 0.0, 0.0, 0.0]}}\n")
    return run_node(tmp, "finger_sim.ros.hand", {"hand": str(hand)})


def view(run: Path, out: Path, scene: Path | None = None) -> Path:
    from finger_sim.view import write_view

    write_view(run, out, scene=scene)
    return out


# -- tests -----------------------------------------------------------------------------------------


def test_log_view_draws_the_logged_states_and_grip(browser: Any, grasp_log: Path, tmp_path: Path) -> None:
    log = read_log(grasp_log)
    states, grip, wrench = log["/joint_states"], log["/grip_force"], log["/contact_wrench/distal"]
    with opened(browser, view(grasp_log, tmp_path / "grasp.html")) as page:
        assert page.locator("circle.object[data-object='cup']").count() == 1
        touching = 0
        for t in (0.1, 0.25, 0.45):  # before contact, on the cup while it settles, at rest on it
            show_time(page, t)
            stamp = assert_drawn_state(page, "grasp_cylinder", states)
            assert abs(stamp * 1e-9 - t) < 1e-3 + 1e-9  # one frame per logged state
            value = page.get_attribute("td[data-column='grip_force']", "data-value")
            assert float(value) == grip[stamp].data, (t, value, grip[stamp].data)
            drawn_t = float(page.get_attribute("g.finger", "data-t"))
            page.wait_for_function("t => Math.abs(document.getElementById('plots').layout.shapes[0].x0 - t) < 1e-12", arg=drawn_t)
            arrows = page.eval_on_selector_all("g.contact-force", "els => els.map(e => [Number(e.dataset.fx), Number(e.dataset.fy)])")
            # the arrows are the distal phalanx's contact forces: their sum is the logged wrench (model Y = −z)
            fx = sum(a[0] for a in arrows)
            fy = sum(a[1] for a in arrows)
            force = wrench[stamp].wrench.force
            assert abs(fx - force.x) < 1e-9 and abs(fy + force.z) < 1e-9, (t, arrows, force)
            touching += bool(arrows)
        assert touching == 2 and grip[stamp].data > 0.1


def test_hand_view_draws_every_finger_in_its_frame(browser: Any, hand_log: Path, tmp_path: Path) -> None:
    log = read_log(hand_log)
    with opened(browser, view(hand_log, tmp_path / "hand.html")) as page:
        assert page.eval_on_selector_all("g.finger", "els => els.map(e => e.dataset.finger)") == ["index", "middle"]
        show_time(page, 0.2)
        stamps = {finger: assert_drawn_state(page, finger, log[f"/{finger}/joint_states"]) for finger in ("index", "middle")}
        assert stamps["index"] == stamps["middle"] == 200_000_000  # one clock
        assert page.locator("circle.object").count() == 1  # the cup of index's scene only


def test_controls_play_step_and_zoom(browser: Any, grasp_log: Path, tmp_path: Path) -> None:
    with opened(browser, view(grasp_log, tmp_path / "grasp.html")) as page:
        last = page.evaluate("window.fingerView.times.length") - 1
        page.select_option("#speed", "10")
        page.click("#play")
        page.wait_for_function(f"document.querySelector('g.finger').dataset.frame === '{last}'", timeout=10_000)
        assert page.inner_text("#play") == "▶"  # paused at the end
        page.click("#prev")
        page.click("#prev")
        page.click("#next")
        assert page.get_attribute("g.finger", "data-frame") == str(last - 1)
        page.keyboard.press("ArrowLeft")
        assert page.get_attribute("g.finger", "data-frame") == str(last - 2)
        home = page.get_attribute("svg.linkage", "viewBox")
        page.hover("svg.linkage")
        page.mouse.wheel(0, -200)
        zoomed = [float(v) for v in page.get_attribute("svg.linkage", "viewBox").split()]
        assert zoomed[2] < float(home.split()[2])  # zoomed in
        page.dblclick("svg.linkage")
        assert page.get_attribute("svg.linkage", "viewBox") == home


@pytest.mark.parametrize("scene", SCENES)
def test_shipped_scene_screenshot(browser: Any, scene: str, tmp_path: Path) -> None:
    from PIL import Image

    from finger_sim.scene import load_scene
    from finger_sim.simulate import simulate

    spec = load_scene(CONFIG / f"{scene}.yaml")
    traj = simulate(spec.with_overrides(duration=min(spec.duration, SCREENSHOT_DURATION_S)), kernel="python")
    csv = tmp_path / f"{scene}.csv"
    traj.write_csv(csv)
    with opened(browser, view(csv, tmp_path / f"{scene}.html", CONFIG / f"{scene}.yaml")) as page:
        show_time(page, float(traj.t[-1]))
        SCREENSHOTS.mkdir(parents=True, exist_ok=True)
        shot = SCREENSHOTS / f"{scene}.png"
        page.locator("svg.linkage").screenshot(path=str(shot))
    grey = np.asarray(Image.open(shot).convert("L").resize(REFERENCE_SIZE, Image.Resampling.LANCZOS), dtype=float)
    reference = REFERENCES / f"{scene}.png"
    if UPDATE_REFERENCES:
        REFERENCES.mkdir(exist_ok=True)
        Image.fromarray(grey.round().astype(np.uint8)).save(reference, optimize=True)
    expected = np.asarray(Image.open(reference).convert("L"), dtype=float)
    difference = float(np.mean(np.abs(grey - expected)))
    assert difference <= SCREENSHOT_TOLERANCE, f"{shot} differs from {reference} by {difference:.2f} grey levels on average"
