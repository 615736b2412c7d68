"""MuJoCo peer of the finger: the spec's four-bar as an MJCF, stepped the way MuJoCo users step it.

The model of spec §1-3 as a kinematic tree plus one loop-closing constraint:

- hinge ``mcp_joint`` at A carries link 1 (proximal); its child body at B carries link 3
  (distal) on hinge ``pip_joint``; hinge ``coupler_joint`` at D carries link 2. All axes are
  +z, the model-plane normal, so MuJoCo's xy-plane is the spec's (X, Y) and a positive
  hinge angle turns from +X towards +Y like the paper's angles.
- an equality ``connect`` pulls together the sites ``C_coupler`` = D + r2 e(θ2) on link 2 and
  ``C_distal`` = B − r3 e(θ3) on link 3 (the spec's B = C + r3 e(θ3)), closing the loop at C.

Body frames are laid out so that qpos = 0 is the extended pose θ_ext, and MuJoCo's joint
angles are the ROS joint positions of spec §6 (mcp = θ1 − θ1_ext, coupler = θ2 − θ2_ext,
pip = β = θ3 + α − θ1). Back to the paper: θ = θ_ext + (q_mcp, q_coupler, q_mcp + q_pip).

Mass properties are the spec's rods: each body's inertial has the link's mass at the spec's
centre of mass and, about the hinge normal z, the rod's inertia about that centre, so the
inertia about A, D and the distal centre of mass equals `FingerParams.inertia_A`, `inertia_D`,
`inertia_G3`. The other axes never enter the planar motion; they are the slender rod's
(transverse y equal to z, axial x a tiny ROD_AXIAL_INERTIA_RATIO of it) because MuJoCo
rejects inertias that break the triangle inequality (Ixx + Iyy ≥ Izz): two tiny axes
cannot be combined with a finite z.

The PIP spring is the stiffness of ``pip_joint`` with springref 0 (V = ½ k β², at rest at
extension); the motor is a ``motor`` actuator on ``mcp_joint`` with gear 1 and unlimited ctrl.
No gravity, no joint damping or armature.

Contact (spec §7), only when objects are given: each phalanx gets a collision capsule of the
spec's radius on its axis (proximal A→B, ρ1; distal B→tip, ρ3), each object a world geom: a
circle is a ``cylinder`` along z (the model-plane normal, long enough that the capsules at
z = 0 only meet its side), a plane a ``plane`` geom whose z axis is the outward normal (MuJoCo's
plane is solid on its −z side, the spec's −n). contype/conaffinity let a phalanx touch an
object and nothing else (capsules contype 1 conaffinity 0, objects 0 and 1). Frictionless
contacts (μ = 0, the spec's default) have condim 1; with μ > 0, condim 3 and sliding friction
μ. MuJoCo's contact law is its own soft constraint (solref/solimp), not Hunt–Crossley: the
rest pose differs from ours by the difference in penetration, while the force that holds the
finger at rest is set by the statics. Without objects, contacts stay disabled.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from finger_sim.effects.contact_geometry import PHALANX_RADII, Circle, Plane, SceneObject
from finger_sim.errors import ConfigError, SimulationDiverged
from finger_sim.kinematics import constraint_norm, distal_offset, extended_pose
from finger_sim.model import FingerParams

#: When in a step (fraction of dt) the held torque is evaluated. Euler and implicitfast take
#: every force at the step's start, so τ(t) is their own consistent choice. RK4 would want τ
#: at its stage times but MuJoCo holds ctrl through all four stages; τ(t) would then add a
#: first-order error (1.4e3× the midpoint's on paper_flexion at dt 1e-3), while τ(t + dt/2)
#: has the exact impulse of a linear ramp and keeps the hold second-order.
TORQUE_TIME_IN_STEP = {"Euler": 0.0, "RK4": 0.5, "implicitfast": 0.0}

#: MuJoCo integrators the peer offers, by their MJCF names.
INTEGRATORS = tuple(TORQUE_TIME_IN_STEP)

#: The paper's PIP spring, N·m/rad (spec §3).
PAPER_SPRING_STIFFNESS = 0.001

#: Axial (rod-axis, x) inertia of each link as a fraction of its transverse inertia:
#: tiny but positive, far above MuJoCo's mjMINVAL (1e-15 kg·m²) for the spec's links.
ROD_AXIAL_INERTIA_RATIO = 1e-6

#: Radius of the visual capsules, m; they have no mass and no collisions.
VISUAL_RADIUS = 0.002

#: Joint names in the paper's order: the coordinates θ1, θ2 and (via β) θ3.
JOINTS = ("mcp_joint", "coupler_joint", "pip_joint")

#: Half-length of a circle's cylinder along z, m: far beyond the capsules' radii, so they meet its side only.
CYLINDER_HALF_LENGTH = 0.05

#: Names of the phalanges' collision capsules (bodies proximal and distal).
PHALANX_GEOMS = ("proximal_capsule", "distal_capsule")

#: Sample times must lie on the step grid to this fraction of a step.
GRID_TOLERANCE = 1e-6

#: When no sample times are given, about this many evenly strided steps are sampled.
DEFAULT_SAMPLE_COUNT = 300


@dataclass(frozen=True)
class EqualitySetting:
    """Solver parameters of the loop-closing ``connect`` (MuJoCo's solref and solimp).

    solref: (timeconst s, dampratio) when positive; (−stiffness 1/s², −damping 1/s) when
    negative (the "direct" form). solimp: (dmin, dmax, width m, midpoint, power), with the
    impedance d clamped by MuJoCo to [1e-4, 0.9999]. With d constant, the constraint
    acceleration is ≈ d·aref + (1 − d)·a_unconstrained, aref = −b·(J v) − k·r.
    """

    name: str
    solref: tuple[float, float]
    solimp: tuple[float, float, float, float, float]


#: What a connect gets when the MJCF says nothing: MuJoCo's defaults.
DEFAULT_EQUALITY = EqualitySetting("default", (0.02, 1.0), (0.9, 0.95, 0.001, 0.5, 2.0))

#: Largest impedance MuJoCo accepts (mjMAXIMP), used flat: d(r) = 0.9999 for every r.
TIGHT_SOLIMP = (0.9999, 0.9999, 0.001, 0.5, 2.0)

#: Tight timeconst in timesteps: the smallest MuJoCo's refsafe allows for a positive timeconst.
#: Measured on paper_flexion (dt 1e-3 and 1e-4): Euler and implicitfast diverge at 1 step;
#: RK4 runs down to 0.5 step but its angle error grows (×1.3 at 1, ×2.2 at 0.5; diverges at
#: 0.25), so 2 steps is both the stiffest stable and the most accurate choice.
TIGHT_TIMECONST_STEPS = 2.0

#: A loop open by more than this fraction of r3 is no longer the finger: the run diverged.
DIVERGED_LOOP_FRACTION = 0.5


#: MuJoCo's default contact solver parameters (the same as a connect's when the MJCF says nothing).
DEFAULT_CONTACT = EqualitySetting("default", DEFAULT_EQUALITY.solref, DEFAULT_EQUALITY.solimp)


#: Tight contact timeconst in timesteps. Measured on grasp_cylinder (RK4, the tight loop): at
#: 1e-4 s a contact at 2 steps chatters at rest (on and off, grip 0–0.37 N over the last 0.2 s);
#: 3 steps comes to rest at 1e-3 and 1e-4 s, with the grip within 2e-6 N of its end value.
TIGHT_CONTACT_TIMECONST_STEPS = 3.0


def tight_contact(timestep: float) -> EqualitySetting:
    """The stiffest contact that stays stable (comes to rest) at `timestep` s: critically damped,
    timeconst TIGHT_CONTACT_TIMECONST_STEPS·timestep, impedance 0.9999: the most rigid contact
    MuJoCo's soft-constraint model gives at that step."""
    return EqualitySetting("tight", (TIGHT_CONTACT_TIMECONST_STEPS * timestep, 1.0), TIGHT_SOLIMP)


def tight_equality(timestep: float) -> EqualitySetting:
    """The stiffest equality that stays stable with every offered integrator at `timestep` s.

    Critically damped (dampratio 1) with timeconst 2·timestep and the largest impedance,
    0.9999 (0.99 makes RK4's error 40× larger). The direct form (−1/tc², −2/tc) is the same
    spring and escapes refsafe's clamp, but a stiffer one is not stable (TIGHT_TIMECONST_STEPS).
    The constraint's compliance error then shrinks like timestep², whatever the integrator's order.
    """
    return EqualitySetting("tight", (TIGHT_TIMECONST_STEPS * timestep, 1.0), TIGHT_SOLIMP)


@dataclass(frozen=True)
class MujocoRun:
    """Samples of one MuJoCo run, in the paper's coordinates.

    t: (N,) s, on the step grid; theta: (N, 3) rad, (θ1, θ2, θ3); loop_violation: (N,) m,
    |C_coupler − C_distal|; cpu_time: s, `time.process_time` over the stepping loop only
    (setting ctrl, mj_step, copying qpos at the N samples).
    """

    t: np.ndarray
    theta: np.ndarray
    loop_violation: np.ndarray
    cpu_time: float
    n_steps: int
    integrator: str
    timestep: float
    equality: EqualitySetting

    @property
    def us_per_step(self) -> float:
        """CPU time per step, µs."""
        return 1e6 * self.cpu_time / self.n_steps


def _xyz(*values: float) -> str:
    """Floats for an MJCF attribute, at full precision (repr round-trips through strtod)."""
    return " ".join(repr(float(v)) for v in values)


def _link(name: str, mass: float, com: float, izz_com: float, length: float) -> str:
    """Inertial and visual geom of a rod along body x from 0 to `length` with its mass centre at `com`."""
    return (
        f'<inertial pos="{_xyz(com, 0, 0)}" mass="{_xyz(mass)}" '
        f'diaginertia="{_xyz(ROD_AXIAL_INERTIA_RATIO * izz_com, izz_com, izz_com)}"/>\n'
        f'<geom name="{name}" type="capsule" fromto="{_xyz(0, 0, 0, length, 0, 0)}" '
        f'size="{_xyz(VISUAL_RADIUS)}" contype="0" conaffinity="0"/>'
    )


def mjcf(
    params: FingerParams,
    *,
    timestep: float,
    integrator: str,
    equality: EqualitySetting = DEFAULT_EQUALITY,
    spring_stiffness: float = PAPER_SPRING_STIFFNESS,
    objects: Sequence[SceneObject] = (),
    radii: tuple[float, float] = PHALANX_RADII,
    contact: EqualitySetting = DEFAULT_CONTACT,
    friction: float = 0.0,
) -> str:
    """The MJCF text of the finger (SI units, radians); qpos = 0 is the extended pose.

    objects: spec §7 circles and planes (none: contacts disabled); radii: the phalanx capsules'
    (ρ1, ρ3), m; contact: solref/solimp of the phalanx–object contacts; friction: μ (0: condim 1).
    """
    p = params
    alpha = distal_offset(p)
    theta2_ext = extended_pose(p)[1]
    d = (-p.r4 * math.cos(p.theta4), -p.r4 * math.sin(p.theta4))
    # C seen from B in the distal frame (x along ψ = θ3 + α): −r3 e(θ3 − ψ) = r3 e(π − α).
    c_distal = (p.r3 * math.cos(math.pi - alpha), p.r3 * math.sin(math.pi - alpha))
    # Rod inertias about their own centres; the hinges add m·(l/2)² back (parallel axes).
    i1 = p.inertia_A - p.m1 * (p.r1 / 2.0) ** 2
    i2 = p.inertia_D - p.m2 * (p.r2 / 2.0) ** 2
    solref, solimp = _xyz(*equality.solref), _xyz(*equality.solimp)
    flags = "" if objects else '\n  <flag contact="disable"/>\n'
    surface = (
        f'condim="{1 if friction == 0.0 else 3}" friction="{_xyz(friction, 0.0, 0.0)}" '
        f'solref="{_xyz(*contact.solref)}" solimp="{_xyz(*contact.solimp)}"'
    )

    def capsule(name: str, length: float, radius: float) -> str:
        if not objects:
            return ""
        return (
            f'<geom name="{name}" type="capsule" fromto="{_xyz(0, 0, 0, length, 0, 0)}" size="{_xyz(radius)}" '
            f'contype="1" conaffinity="0" {surface}/>\n'
        )

    world = "".join(_object_geom(obj, surface) for obj in objects)
    return f"""<mujoco model="finger_fourbar">
<compiler angle="radian" inertiafromgeom="false"/>
<option timestep="{_xyz(timestep)}" integrator="{integrator}" gravity="0 0 0">{flags}</option>
<worldbody>
{world}<body name="proximal">
<joint name="mcp_joint" type="hinge" axis="0 0 1"/>
{_link("proximal", p.m1, p.r1 / 2.0, i1, p.r1)}
{capsule(PHALANX_GEOMS[0], p.r1, radii[0])}<body name="distal" pos="{_xyz(p.r1, 0, 0)}">
<joint name="pip_joint" type="hinge" axis="0 0 1" stiffness="{_xyz(spring_stiffness)}" springref="0"/>
{_link("distal", p.m3, p.L3 / 2.0, p.inertia_G3, p.L3)}
{capsule(PHALANX_GEOMS[1], p.L3, radii[1])}<site name="C_distal" pos="{_xyz(*c_distal, 0)}"/>
<site name="tip" pos="{_xyz(p.L3, 0, 0)}"/>
</body>
</body>
<body name="coupler" pos="{_xyz(*d, 0)}" axisangle="{_xyz(0, 0, 1, theta2_ext)}">
<joint name="coupler_joint" type="hinge" axis="0 0 1"/>
{_link("coupler", p.m2, p.r2 / 2.0, i2, p.r2)}
<site name="C_coupler" pos="{_xyz(p.r2, 0, 0)}"/>
</body>
</worldbody>
<equality>
<connect name="loop_C" site1="C_coupler" site2="C_distal" solref="{solref}" solimp="{solimp}"/>
</equality>
<actuator>
<motor name="mcp_motor" joint="mcp_joint" gear="1" ctrllimited="false"/>
</actuator>
</mujoco>
"""


def _object_geom(obj: SceneObject, surface: str) -> str:
    """A world geom of one spec §7 object: a circle as a cylinder along z, a plane with z along its normal."""
    if isinstance(obj, Circle):
        return (
            f'<geom name="{obj.name}" type="cylinder" pos="{_xyz(*obj.center, 0)}" '
            f'size="{_xyz(obj.radius, CYLINDER_HALF_LENGTH)}" contype="0" conaffinity="1" {surface}/>\n'
        )
    assert isinstance(obj, Plane)
    return (
        f'<geom name="{obj.name}" type="plane" pos="{_xyz(*obj.point, 0)}" zaxis="{_xyz(*obj.normal, 0)}" '
        f'size="0 0 1" contype="0" conaffinity="1" {surface}/>\n'
    )


class MujocoFinger:
    """The finger's MJCF compiled to a `mujoco.MjModel`, with the maps to the paper's coordinates.

    Holds the model only; states live in the `mujoco.MjData` objects `make_data` returns.
    """

    def __init__(
        self,
        params: FingerParams,
        *,
        timestep: float,
        integrator: str,
        equality: EqualitySetting = DEFAULT_EQUALITY,
        spring_stiffness: float = PAPER_SPRING_STIFFNESS,
        objects: Sequence[SceneObject] = (),
        radii: tuple[float, float] = PHALANX_RADII,
        contact: EqualitySetting = DEFAULT_CONTACT,
        friction: float = 0.0,
    ) -> None:
        if integrator not in INTEGRATORS:
            raise ConfigError("integrator", f"one of {INTEGRATORS}", integrator)
        if not (math.isfinite(timestep) and timestep > 0.0):
            raise ConfigError("timestep", "a finite value > 0 in s", timestep)
        if not (math.isfinite(spring_stiffness) and spring_stiffness >= 0.0):
            raise ConfigError("spring_stiffness", "a finite value ≥ 0 in N·m/rad", spring_stiffness)
        self.params = params
        self.theta_ext = np.array(extended_pose(params))
        self.xml = mjcf(
            params, timestep=timestep, integrator=integrator, equality=equality, spring_stiffness=spring_stiffness,
            objects=objects, radii=radii, contact=contact, friction=friction,
        )
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        ids = [self.model.joint(name).id for name in JOINTS]
        #: qpos / qvel addresses of (mcp, coupler, pip)
        self.qpos_index = np.array([self.model.jnt_qposadr[i] for i in ids])
        self.dof_index = np.array([self.model.jnt_dofadr[i] for i in ids])
        self.site_ids = (self.model.site("C_coupler").id, self.model.site("C_distal").id)
        self.motor_id = self.model.actuator("mcp_motor").id
        #: geom ids of the phalanx capsules and of the objects (empty without objects)
        self.phalanx_geoms = frozenset(self.model.geom(n).id for n in PHALANX_GEOMS) if objects else frozenset()
        self.object_geoms = frozenset(self.model.geom(obj.name).id for obj in objects)
        self._force = np.zeros(6)

    def grip_force(self, data: mujoco.MjData) -> float:
        """Σ F_n, N: the normal forces (`mj_contactForce`, contact frame) of the phalanx–object contacts."""
        total = 0.0
        for i in range(data.ncon):
            c = data.contact[i]
            pair = {int(c.geom1), int(c.geom2)}
            if pair & self.phalanx_geoms and pair & self.object_geoms:
                mujoco.mj_contactForce(self.model, data, i, self._force)
                total += float(self._force[0])
        return total

    def to_paper(self, qpos: np.ndarray) -> np.ndarray:
        """(θ1, θ2, θ3), rad, from qpos of shape (..., nq): θ = θ_ext + (q_mcp, q_coupler, q_mcp + q_pip)."""
        q = np.asarray(qpos)[..., self.qpos_index]
        theta = self.theta_ext + q
        theta[..., 2] += q[..., 0]
        return theta

    def joint_angles(self, theta: Sequence[float]) -> np.ndarray:
        """(q_mcp, q_coupler, q_pip), rad, of a paper pose (θ1, θ2, θ3): the inverse of `to_paper`."""
        d = np.asarray(theta, dtype=float) - self.theta_ext
        return np.array([d[0], d[1], d[2] - d[0]])

    def make_data(
        self, theta: Sequence[float] | None = None, theta_dot: Sequence[float] = (0.0, 0.0, 0.0)
    ) -> mujoco.MjData:
        """A state at the paper pose θ (rad; default θ_ext) with rates θ' (rad/s), forwarded once."""
        data = mujoco.MjData(self.model)
        data.qpos[self.qpos_index] = self.joint_angles(self.theta_ext if theta is None else theta)
        # θ' = T q' with T = [[1,0,0],[0,1,0],[1,0,1]], so q' = (θ1', θ2', θ3' − θ1').
        w = np.asarray(theta_dot, dtype=float)
        data.qvel[self.dof_index] = (w[0], w[1], w[2] - w[0])
        mujoco.mj_forward(self.model, data)
        return data

    def loop_violation(self, theta: np.ndarray) -> np.ndarray:
        """|C_coupler − C_distal|, m, for each row of θ (N, 3): the closure residual |Φ(θ)|."""
        return np.array([constraint_norm(self.params, tuple(row)) for row in np.atleast_2d(theta)])


def _grid_steps(times: np.ndarray, timestep: float, key: str) -> np.ndarray:
    """Step indices of times on the grid k·timestep; ConfigError when one is off it."""
    steps = np.rint(times / timestep)
    if not np.all(np.abs(times / timestep - steps) <= GRID_TOLERANCE):
        raise ConfigError(key, f"times on the step grid k·{timestep!r} s", times)
    return steps.astype(int)


def run_mujoco(
    params: FingerParams,
    *,
    torque: Callable[[float], float],
    t_end: float,
    timestep: float,
    integrator: str,
    equality: EqualitySetting = DEFAULT_EQUALITY,
    spring_stiffness: float = PAPER_SPRING_STIFFNESS,
    sample_times: Sequence[float] | None = None,
) -> MujocoRun:
    """Step the MJCF from rest at θ_ext over [0, t_end] s under the motor torque τ(t), N·m.

    The torque is set in ctrl before each mj_step and held over the step, as MuJoCo users
    do, at the time TORQUE_TIME_IN_STEP[integrator] into the step: the step's start for
    Euler and implicitfast (their other forces are taken there too), its midpoint for RK4.
    The schedule is evaluated before the timed loop, which then only sets ctrl and steps.

    sample_times: s, ascending, on the step grid within [0, t_end]; default about
    DEFAULT_SAMPLE_COUNT evenly strided steps including 0 and t_end.
    Raises SimulationDiverged when MuJoCo reports a bad acceleration (it would otherwise
    silently reset the state to qpos0 and go on), or when a sample is non-finite or has the
    loop open by more than DIVERGED_LOOP_FRACTION·r3 (RK4 can blow up without the warning).
    """
    finger = MujocoFinger(
        params, timestep=timestep, integrator=integrator, equality=equality, spring_stiffness=spring_stiffness
    )
    if not (math.isfinite(t_end) and t_end > 0.0):
        raise ConfigError("t_end", "a finite value > 0 in s", t_end)
    n_steps = int(_grid_steps(np.array([t_end]), timestep, "t_end")[0])
    if sample_times is None:
        stride = max(1, n_steps // DEFAULT_SAMPLE_COUNT)
        samples = np.unique(np.append(np.arange(0, n_steps + 1, stride), n_steps))
    else:
        samples = _grid_steps(np.asarray(sample_times, dtype=float), timestep, "sample_times")
        if samples.size == 0 or samples[0] < 0 or samples[-1] > n_steps or np.any(np.diff(samples) <= 0):
            raise ConfigError("sample_times", f"ascending times within [0, {t_end!r}] s", sample_times)
    # Stop at every sample, and at n_steps so the timed work is always the whole run.
    stops = samples.tolist() + ([n_steps] if samples[-1] < n_steps else [])
    offset = TORQUE_TIME_IN_STEP[integrator]
    taus = [float(torque((k + offset) * timestep)) for k in range(n_steps)]
    chunks = [taus[a:b] for a, b in zip([0, *stops[:-1]], stops)]

    model = finger.model
    data = finger.make_data()
    qpos_samples = np.empty((len(stops), model.nq))
    ctrl, motor, qpos, step = data.ctrl, finger.motor_id, data.qpos, mujoco.mj_step
    start = time.process_time()
    for j, chunk in enumerate(chunks):
        for tau in chunk:
            ctrl[motor] = tau
            step(model, data)
        qpos_samples[j] = qpos
    cpu_time = time.process_time() - start

    theta = finger.to_paper(qpos_samples[: samples.size])
    loop = finger.loop_violation(theta)
    bad = data.warning[mujoco.mjtWarning.mjWARN_BADQACC]
    if bad.number > 0 or not np.all(np.isfinite(theta)) or loop.max() > DIVERGED_LOOP_FRACTION * params.r3:
        raise SimulationDiverged(
            f"MuJoCo {integrator} at timestep {timestep!r} s with solref {equality.solref}: "
            f"{bad.number} bad-acceleration reset(s) (last at dof {bad.lastinfo}), "
            f"largest loop violation {loop.max()!r} m"
        )
    return MujocoRun(
        t=samples * timestep,
        theta=theta,
        loop_violation=loop,
        cpu_time=cpu_time,
        n_steps=n_steps,
        integrator=integrator,
        timestep=timestep,
        equality=equality,
    )
