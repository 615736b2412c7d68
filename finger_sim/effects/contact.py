"""Contact of the phalanges with the scene's objects: the force element of spec §7.

Each phalanx is a capsule in the model plane: the proximal one the segment A→B swept by ρ1,
the distal one B→tip (tip = B + L3 e(ψ), ψ = θ3 + α) swept by ρ3. A *candidate* is one place
where a phalanx may touch an object:

- a circle (centre c, radius R) and a phalanx: p is the point of the phalanx's axis segment
  closest to c, δ = ρ + R − |p − c|, n_c = (p − c)/|p − c|;
- a plane (point o, outward normal n) and one end of a phalanx's axis segment (B for either
  phalanx, the tip for the distal one; A is fixed, so its force does no work and is left out):
  p is that end, δ = ρ − n·(p − o), n_c = n. Both ends of a segment are candidates and their
  forces add up, so V_c stays smooth when a phalanx lies flat on the plane.

Contact while δ > 0: F_n = max(0, k δ^e (1 + d δ')) (Hunt–Crossley), δ' = −n_c·ṗ with ṗ the
velocity of the phalanx's material point at p; F_t = −μ F_n tanh(v_t / v_s) along t_c = n_c
turned by +90°; F = F_n n_c + F_t t_c on the phalanx at p; Q_c = J_pᵀ F with J_p = ∂p/∂q of
that material point (virtual work). For a circle, p slides along the segment, but the sliding
is normal to n_c (or p is clamped at an end), so J_pᵀ n_c F_n = −∂V_c/∂q exactly with
V_c = k δ^(e+1)/(e+1). J_p has no θ2 column: the coupler touches nothing.

The arithmetic (each candidate's geometry, the force) is `effects.contact_law`'s plain functions and
the walk over the candidates is `effects.contact_candidates.walk_candidates`, both of which the compiled
kernel compiles as they are; this element keeps the candidates and sums. Scalar `math` throughout:
`force` runs in every stage of every step. Candidates that cannot touch anywhere are dropped when the
element is built; the rest are skipped by a cheap bound (the distal segment lies within L3 of B) before
the distal direction e(ψ) is evaluated.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from finger_sim.effects.base import Vec3, effect
from finger_sim.effects.contact_law import contact_force, gap_gradient, generalized, point_velocity
from finger_sim.effects.contact_candidates import COUNTS, HEADER, RECORD_SIZE, walk_candidates
from finger_sim.effects.contact_geometry import PHALANX_RADII, Circle, ContactParams, Plane, SceneObject, Vec2
from finger_sim.effects.contact_outputs import (CONTACT_FORCES, CONTACT_OUTPUTS, CONTACT_WRENCHES, GRIP_FORCE,
                                               MOTION_POWER)
from finger_sim.errors import ConfigError
from finger_sim.effects.base import CONTACT
from finger_sim.kinematics import distal_offset
from finger_sim.model import FingerParams

if TYPE_CHECKING:
    from finger_sim.scene import Scene

PHALANGES = ("proximal", "distal")
PROXIMAL, DISTAL = 0, 1
#: An object may overlap a phalanx this much (m) at a scene's initial state: round-off in
#: hand-placed coordinates, not a contact that would start with a jolt.
OVERLAP_TOLERANCE = 1e-4
#: The contact force (N) at which `modal` sizes the contact mode when the pose presses less
#: (or not at all): a firm grip, about the force of the default k_c = 1e5 at δ = 1 mm (3.2 N).
#: The stability check samples poses along the whole range, mostly out of contact; this floor
#: lets it see the stiff contact mode there (spec §7: ≈700 rad/s at k_c = 1e5, a few
#: thousand rad/s at k_c = 1e7, the same force needing a much smaller δ).
DESIGN_FORCE = 3.0


@dataclass(frozen=True)
class ContactPoint:
    """One active contact: where, along which normal, and the force on the phalanx (model plane)."""

    phalanx: str  # "proximal" or "distal"
    object: str  # the object's name
    point: Vec2  # p on the phalanx's axis, m
    normal: Vec2  # n_c, from the object towards p
    penetration: float  # δ, m
    normal_force: float  # F_n, N
    force: Vec2  # F = F_n n_c + F_t t_c on the phalanx, N


# One evaluated candidate: (phalanx, object index, δ, px, py, nx, ny, j1x, j1y, j3x, j3y).
_Hit = tuple[int, int, float, float, float, float, float, float, float, float, float]


class Contact:
    """Hunt–Crossley contact with regularized Coulomb friction between the phalanx capsules and
    fixed circles and planes (spec §7). Immutable after construction, but for what it keeps of the last
    state asked (`_hits`, `_block_at`)."""

    #: Q depends on q' through δ' δ^e and tanh(v_t / v_s): not affine in q'.
    affine_in_velocity: ClassVar[bool] = False
    kernel_code: ClassVar[int] = CONTACT
    #: F_n ∝ δ^e is not smooth at onset: onset and release are events (see `gaps`).
    smooth: ClassVar[bool] = False

    def __init__(
        self,
        params: FingerParams,
        alpha: float,
        radii: Vec2 = PHALANX_RADII,
        contact: ContactParams = ContactParams(),
        objects: Sequence[SceneObject] = (),
    ) -> None:
        self.params, self.alpha, self.radii, self.contact = params, alpha, tuple(radii), contact
        self.objects = tuple(objects)
        r1, l3 = params.r1, params.L3
        rho1, rho3 = radii
        self._r1, self._l3 = r1, l3
        self._k, self._e, self._d = contact.stiffness, contact.exponent, contact.damping
        self._mu, self._vs = contact.friction, contact.slip_velocity
        # Each object's k_c and d_c: its own (`ObjectProperties`) or the scene's. The compiled
        # law has one k_c and d_c: the objects' one law when they all share it (e.g. a single soft
        # or rigid object), else the scene steps in Python.
        self._obj_k = tuple(self._k if o.properties.stiffness is None else o.properties.stiffness for o in self.objects)
        self._obj_d = tuple(self._d if o.properties.damping is None else o.properties.damping for o in self.objects)
        laws = set(zip(self._obj_k, self._obj_d))
        self._kernel_k, self._kernel_d = next(iter(laws)) if len(laws) == 1 else (self._k, self._d)
        # Objects with a prescribed motion (`ObjectMotion`): the gaps, V_c and the force depend
        # on t too (`gaps_at`, `gap_rates`, `potential_at`), and the Simulator asks for those.
        self._motions = tuple(o.properties.motion for o in self.objects)
        self.time_varying = any(m is not None for m in self._motions)
        if len(laws) > 1 or self.time_varying:
            self.kernel_code = None  # type: ignore[misc]  # no compiled form: see kernel.layout
        # Stiffness and damping of the contact law at DESIGN_FORCE: δ_d = (F_d / k)^(1/e),
        # the stiffest object's (the scene's k_c and d_c count only where an object takes them).
        k_max, d_max = max(self._obj_k, default=self._k), max(self._obj_d, default=self._d)
        delta_d = (DESIGN_FORCE / k_max) ** (1.0 / self._e)
        self._k_design = k_max * self._e * delta_d ** (self._e - 1.0)
        self._c_design = d_max * DESIGN_FORCE
        self._friction_design = self._mu * DESIGN_FORCE / self._vs
        # Candidates, (phalanx, object index, their floats in the block), kept only where some pose
        # can reach them (|p − A| ≤ r1 on the proximal phalanx, ≤ r1 + L3 on the distal one).
        prox_circles, dist_circles, ends, tips = [], [], [], []
        # (A moving object is a candidate wherever it is: it is never dropped nor bounded.)
        for i, obj in enumerate(self.objects):
            moving = self._motions[i] is not None
            if isinstance(obj, Circle):
                cx, cy = obj.center
                if moving or math.hypot(cx, cy) <= r1 + rho1 + obj.radius:
                    prox_circles.append((PROXIMAL, i, cx, cy, rho1 + obj.radius))
                if moving or math.hypot(cx, cy) <= r1 + l3 + rho3 + obj.radius:
                    reach = math.inf if moving else l3 + rho3 + obj.radius
                    dist_circles.append((DISTAL, i, cx, cy, rho3 + obj.radius, reach * reach))
            else:
                (ox, oy), (nx, ny) = obj.point, obj.normal
                height_a = -(nx * ox + ny * oy)  # n·(A − o)
                for phalanx, rho in ((PROXIMAL, rho1), (DISTAL, rho3)):
                    if moving or height_a - r1 < rho:
                        ends.append((phalanx, i, ox, oy, nx, ny, rho))
                if moving or height_a - r1 - l3 < rho3:
                    tips.append((DISTAL, i, ox, oy, nx, ny, rho3, math.inf if moving else l3 + rho3))
        # The flat block `contact_candidates.walk_candidates` reads (its law header as built: `kernel_params`
        # reads the law's current one), each candidate's (phalanx, object index) in its order, and where a
        # moving object's position sits in it (its offset is added there).
        kinds = (prox_circles, dist_circles, ends, tips)
        self._block = tuple(float(x) for x in (self._r1, self._l3, self.alpha, self._kernel_k, self._e, self._kernel_d,
                                               self._mu, self._vs, *map(len, kinds), *(x for kind in kinds
                                                                                       for c in kind for x in c[2:])))
        self._owners = tuple(c[:2] for kind in kinds for c in kind)
        slots: dict[int, list[int]] = {}
        j = HEADER
        for size, kind in zip(RECORD_SIZE, kinds):
            for c in kind:
                if self._motions[c[1]] is not None:
                    slots.setdefault(c[1], []).append(j)
                j += size
        #: each moving object's motion and the positions of its candidates' (x, y) in the block
        self._moving = tuple((self._motions[i], tuple(js)) for i, js in slots.items())
        #: (t, the block at t): the last one `_block_at` built, never changed once kept
        self._moved: tuple[float, list[float]] = (math.nan, [])
        #: per kind of `_hits` (only touching, every candidate): its last (t, θ1, θ3) and list, kept unchanged
        self._kept: list[tuple[tuple[float, float, float] | None, list[_Hit]]] = [(None, []), (None, [])]

    def kernel_params(self) -> tuple[float, ...]:
        """The candidates' flat block (`effects.contact_candidates`) with the law's current header (k, d: the
        objects' one law; μ as the element holds it now): what `finger_sim.kernel.numerics` reads."""
        law = (self._r1, self._l3, self.alpha, self._kernel_k, self._e, self._kernel_d, self._mu, self._vs)
        return tuple(float(x) for x in law) + self._block[COUNTS:]

    # -- geometry ------------------------------------------------------------------------
    def _hits(self, q: Vec3, all_candidates: bool, t: float = 0.0) -> list[_Hit]:
        """The evaluated candidates at q (and t, for moving objects): those with δ > 0, or every
        one (for gaps and modal); `contact_candidates.walk_candidates` picks and orders them.

        J_p has two non-zero columns, returned as vectors j1 = ∂p/∂θ1 and j3 = ∂p/∂θ3 (m/rad). The last
        list of each kind is kept and given again at the same (t, θ1, θ3): a step asks several times at one
        state (the force, the holding test, the stick speed); callers only read it.
        """
        key = (t, q[0], q[2])
        kept_key, hits = self._kept[all_candidates]
        if kept_key != key:
            hits = walk_candidates(self._block_at(t) if self._moving else self._block, 0, q[0], q[2],
                                   all_candidates, [], (all_candidates, self._owners))
            self._kept[all_candidates] = (key, hits)  # one assignment: a reader sees a whole pair
        return hits

    def _block_at(self, t: float) -> list[float]:
        """The block with the moving objects where they are at t (s). The last one is kept: a step asks
        at one t several times (the force, the gaps and their rates, the stick speed)."""
        last_t, block = self._moved
        if t != last_t:
            block = list(self._block)
            for motion, slots in self._moving:
                dx, dy = motion.offset(t)
                for j in slots:
                    block[j] += dx
                    block[j + 1] += dy
            self._moved = (t, block)  # one assignment: a reader sees a whole (t, block) pair
        return block

    def _forces(self, hit: _Hit, v: Vec3, t: float = 0.0) -> tuple[float, float, float]:
        """(F_n, Fx, Fy), N, of one candidate in contact: Hunt–Crossley normal force plus friction.
        The velocity is the phalanx's relative to the object (ṗ − ċ for a moving one)."""
        _, i, d, _, _, nx, ny, *_ = hit
        vx, vy = self._velocity(hit, v, t)
        return contact_force(d, nx, ny, vx, vy, self._obj_k[i], self._e, self._obj_d[i], self._mu, self._vs)

    def _velocity(self, hit: _Hit, v: Vec3, t: float) -> tuple[float, float]:
        """ṗ (m/s) of a candidate's point, relative to its object (ṗ − ċ for a moving one)."""
        vx, vy = point_velocity(*hit[7:], v[0], v[2])
        motion = self._motions[hit[1]] if self.time_varying else None
        if motion is not None:
            cvx, cvy = motion.velocity(t)
            vx, vy = vx - cvx, vy - cvy
        return vx, vy

    # -- the ForceElement protocol -------------------------------------------------------
    def force(self, t: float, q: Vec3, v: Vec3) -> Vec3:
        """Q_c = Σ J_pᵀ F over the candidates in contact, N·m."""
        q1 = q3 = 0.0
        for hit in self._hits(q, False, t):
            _, fx, fy = self._forces(hit, v, t)
            f1, f3 = generalized(*hit[7:], fx, fy)
            q1 += f1
            q3 += f3
        return (q1, 0.0, q3)

    def potential(self, q: Vec3) -> float:
        """V_c = Σ k δ^(e+1)/(e+1), J."""
        e1 = self._e + 1.0
        return sum(self._obj_k[hit[1]] * hit[2] ** e1 / e1 for hit in self._hits(q, False))

    def potential_at(self, t: float, q: Vec3) -> float:
        """V_c at time t (moving objects where they are then), J."""
        e1 = self._e + 1.0
        return sum(self._obj_k[hit[1]] * hit[2] ** e1 / e1 for hit in self._hits(q, False, t))

    def gaps_at(self, t: float, q: Vec3) -> tuple[float, ...]:
        """`gaps` with the moving objects where they are at t (s)."""
        return tuple(-hit[2] for hit in self._hits(q, True, t))

    def gap_rates(self, t: float, q: Vec3, v: Vec3) -> tuple[float, ...]:
        """d gap/dt of every candidate at (t, q, q'), m/s: n_c·(J_p q' − ċ) (the object's own
        velocity ċ moves the gap too; the closest point's sliding is normal to n_c)."""
        out = []
        for hit in self._hits(q, True, t):
            vx, vy = self._velocity(hit, v, t)
            out.append(hit[5] * vx + hit[6] * vy)
        return tuple(out)

    def motion_power(self, t: float, q: Vec3, v: Vec3) -> float:
        """W: the power the prescribed motions put into the finger, Σ F·ċ over the contacts with
        moving objects (F the force on the phalanx): d(T + V + V_c)/dt gains it (spec §7's
        balance with V_c moving: ∂V_c/∂c·ċ = F_n n_c·ċ, and the damping and friction act on ṗ − ċ)."""
        power = 0.0
        for hit in self._hits(q, False, t):
            motion = self._motions[hit[1]]
            if motion is not None:
                _, fx, fy = self._forces(hit, v, t)
                cvx, cvy = motion.velocity(t)
                power += fx * cvx + fy * cvy
        return power

    def modal(self, q: Vec3, n: Vec3) -> tuple[float, float]:
        """(nᵀKn, nᵀCn): the contact's stiffness and damping along a direction n of q.

        Per candidate, with a = n_c·J_p n and b = t_c·J_p n (m per unit of n): stiffness
        k e δ^(e−1) a², damping k d δ^e a² (Hunt–Crossley) + (μ F_n / v_s) b² (the slope of
        the regularized friction at v_t = 0), at the δ of q. The geometric term k δ^e n_cᵀ
        (∂²p/∂q²)[n, n] is left out (it is F_n times a curvature: small beside k e δ^(e−1)).
        Each sum is then bounded below by the stiffest single candidate at DESIGN_FORCE, so
        the stability check sees the contact mode at poses out of contact too.
        """
        e, n1, n3 = self._e, n[0], n[2]
        stiff = damp = stiff_floor = damp_floor = 0.0
        for hit in self._hits(q, True):
            _, i, d, _, _, nx, ny, j1x, j1y, j3x, j3y = hit
            k = self._obj_k[i]
            jx, jy = j1x * n1 + j3x * n3, j1y * n1 + j3y * n3
            a2 = (nx * jx + ny * jy) ** 2
            b2 = (nx * jy - ny * jx) ** 2
            if d > 0.0:
                fn = k * d**e
                stiff += k * e * d ** (e - 1.0) * a2
                damp += self._obj_d[i] * fn * a2 + self._mu * fn / self._vs * b2
            stiff_floor = max(stiff_floor, self._k_design * a2)
            damp_floor = max(damp_floor, self._c_design * a2 + self._friction_design * b2)
        return (max(stiff, stiff_floor), max(damp, damp_floor))

    def gaps(self, q: Vec3) -> tuple[float, ...]:
        """−δ of every candidate (m), in a fixed order: onset and release where one changes sign."""
        return tuple(-hit[2] for hit in self._hits(q, True))

    def impact(self, index: int) -> None:
        """None: onset and release only make Q_c change non-smoothly (a kink, no velocity jump)."""
        return None

    def gap_gradient(self, index: int, q: Vec3) -> Vec3:
        """∂gap/∂q = n_cᵀ J_p of candidate `index` (m/rad): gap = −δ, δ' = −n_c·J_p q'."""
        g1, g3 = gap_gradient(*self._hits(q, True)[index][5:])
        return (g1, 0.0, g3)

    def outputs(self, t: float, q: Vec3, v: Vec3) -> Mapping[str, float]:
        """grip_force = Σ F_n (N) and the force on each phalanx, N, model plane (sum over objects)."""
        grip, phalanx_forces = self._totals(q, v, t)
        out = {GRIP_FORCE.name: grip}
        for (x, y), force in zip(CONTACT_FORCES.values(), phalanx_forces):  # proximal, distal
            out[x.name], out[y.name] = force[0], force[1]
        if self.time_varying:
            out[MOTION_POWER.name] = self.motion_power(t, q, v)  # W, only with moving objects
        return out

    def wrenches(self, t: float, q: Vec3, v: Vec3) -> tuple[Vec3, Vec3]:
        """(Fx, Fy, Mz) on the proximal and on the distal phalanx (`CONTACT_WRENCHES`): the contact force (N,
        model plane, sum over objects) and its moment about the frame origin A (N·m, about +Z of the
        model plane), each force acting at its contact point p on the phalanx's axis."""
        return self._totals(q, v, t)[1]

    # -- reports -------------------------------------------------------------------------
    def contacts(self, t: float, q: Vec3, v: Vec3) -> tuple[ContactPoint, ...]:
        """Every active contact (δ > 0) with its point, normal and force."""
        out = []
        for hit in self._hits(q, False, t):
            fn, fx, fy = self._forces(hit, v, t)
            phalanx, i, d, px, py, nx, ny = hit[:7]
            out.append(ContactPoint(PHALANGES[phalanx], self.objects[i].name, (px, py), (nx, ny), d, fn, (fx, fy)))
        return tuple(out)

    def candidates(self) -> tuple[tuple[str, str], ...]:
        """(phalanx, object name) of every candidate, in `gaps` order."""
        return tuple((PHALANGES[hit[0]], self.objects[hit[1]].name) for hit in self._hits((0.0, 0.0, 0.0), True))

    def object_forces(self, t: float, q: Vec3, v: Vec3) -> tuple[float, ...]:
        """The normal force on each object (N, Σ F_n over its contacts), in `objects` order:
        what a `break_force` is compared with."""
        out = [0.0] * len(self.objects)
        for hit in self._hits(q, False, t):
            out[hit[1]] += self._forces(hit, v, t)[0]
        return tuple(out)

    def check_clearance(self, q: Vec3, tolerance: float = OVERLAP_TOLERANCE) -> None:
        """ConfigError naming `objects[i]` if an object overlaps a phalanx at q by more than
        `tolerance` (m), e.g. at a scene's initial state. Also covers the fixed end A."""
        for phalanx, i, d, *_ in self._hits(q, True):
            if d > tolerance:
                self._refuse_overlap(i, PHALANGES[phalanx], d, tolerance)
        rho1 = self.radii[0]
        for i, obj in enumerate(self.objects):
            if isinstance(obj, Plane):
                d = rho1 + (obj.normal[0] * obj.point[0] + obj.normal[1] * obj.point[1])  # ρ1 − n·(A − o)
                if d > tolerance:
                    self._refuse_overlap(i, "proximal", d, tolerance)

    def _refuse_overlap(self, i: int, phalanx: str, depth: float, tolerance: float) -> None:
        raise ConfigError(
            f"objects[{i}]",
            f"an object clear of the phalanges at the initial state (overlap ≤ {tolerance:g} m)",
            f"'{self.objects[i].name}' overlaps the {phalanx} phalanx by {depth:.4g} m",
        )

    def _totals(self, q: Vec3, v: Vec3, t: float = 0.0) -> tuple[float, tuple[Vec3, Vec3]]:
        """Σ F_n, N, and per phalanx (Fx, Fy, Mz about A)."""
        grip = 0.0
        sums = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
        for hit in self._hits(q, False, t):
            fn, fx, fy = self._forces(hit, v, t)
            grip += fn
            acc, px, py = sums[hit[0]], hit[3], hit[4]
            acc[0] += fx
            acc[1] += fy
            acc[2] += px * fy - py * fx
        return grip, (tuple(sums[0]), tuple(sums[1]))  # type: ignore[return-value]


@effect("contact", "Hunt–Crossley contact of the phalanx capsules with the scene's objects (spec §7)",
        outputs=CONTACT_OUTPUTS, wrenches=CONTACT_WRENCHES)
def build_contact(scene: "Scene") -> Contact | None:
    """The contact element of a scene with objects; None (no element, no cost) without any."""
    objects = tuple(getattr(scene, "objects", ()) or ())
    if not objects:
        return None
    args = (scene.params, distal_offset(scene.params), getattr(scene, "phalanx_radius", PHALANX_RADII),
            getattr(scene, "contact", ContactParams()), objects)
    law = getattr(scene, "friction_law", None)
    if law is not None and law.model == "stick_slip":  # spec §7's exact stick and slip
        from finger_sim.effects.friction_modes import StickSlipContact

        return StickSlipContact(*args, law=law)
    return Contact(*args)
