"""An independent reference for scenes with contact and joint stops (spec §3, §4, §7).

Nothing here imports finger_sim: the dynamics are test/reference.py's (rigid-body mass matrix,
dense 5×5 KKT solve), the contact law is spec §7 written again (capsule axes, Hunt–Crossley normal
force, regularized Coulomb friction, J_pᵀF with the material point's Jacobian written by hand), and
the MCP stops are spec §3's impacts v⁺ = −e v⁻. scipy's solve_ivp (DOP853 at rtol 1e-11) integrates
each smooth piece and stops at every torque switch, contact onset or release (a zero of δ) and stop
impact (solve_ivp events), where it restarts. A finger whose rebound off a stop would rise no
higher than `rest_height` rests on the stop until the free acceleration stops pushing into it (located
inside the piece as a solve_ivp event, `_release`): the rest convention of the stepping code (a cut of
the impacts' Zeno series), the one thing taken from it.

An object may carry its own `stiffness` and `damping` (spec §7's k_c, d_c for that object) and a
prescribed `motion` (push or vibration, the scene schema's): its centre or point then moves by
c(t) − c = s(t) u, the contact's velocity is the phalanx's relative to it, and the motion's kinks
(where s'' jumps) are restart points like a torque switch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

import reference as ref

RTOL, ATOL = 1e-11, 1e-13
#: A contact or stop gap this close to zero counts as on it when choosing its side at a restart.
ON_GAP = 1e-13


@dataclass(frozen=True)
class ContactLaw:
    k: float = 1e5  # N/m^e
    e: float = 1.5
    d: float = 1.5  # s/m
    mu: float = 0.0
    vs: float = 1e-3  # m/s
    rho: tuple[float, float] = (0.008, 0.007)  # m, proximal and distal capsule radii


def motion_offset(obj: dict, t: float) -> tuple[np.ndarray, np.ndarray]:
    """(c(t) − c, ċ(t)) of an object (m, m/s): zero without a `motion`. Push: s = L (1 − cos(π (t − t0)/T))/2
    over [t0, t0 + T], L after; vibration: s = A (1 − cos(2π f (t − t0)))/2 from t0 on."""
    m = obj.get("motion")
    if m is None:
        return np.zeros(2), np.zeros(2)
    u = np.array(m["direction"], dtype=float)
    u /= np.linalg.norm(u)
    x = t - m.get("start", 0.0)
    if m["type"] == "push":
        extent, w, end = m["distance"], math.pi / m["duration"], m["duration"]
    else:
        extent, w, end = m["amplitude"], 2.0 * math.pi * m["frequency"], math.inf
    if x <= 0.0:
        return np.zeros(2), np.zeros(2)
    if x >= end:
        return extent * u, np.zeros(2)
    return 0.5 * extent * (1.0 - math.cos(w * x)) * u, 0.5 * extent * w * math.sin(w * x) * u


def motion_kinks(objects, t_end: float) -> list[float]:
    """Times where an object's s'' jumps (the start and end of a push, the start of a vibration), s."""
    out = []
    for obj in objects:
        m = obj.get("motion")
        if m is not None:
            out.append(m.get("start", 0.0))
            if m["type"] == "push":
                out.append(m.get("start", 0.0) + m["duration"])
    return [t for t in out if 0.0 < t < t_end]


def _candidates(q, objects, rho, t: float = 0.0):
    """(δ, n, J) of every contact candidate (spec §7) at time t (s, for moving objects): J = ∂p/∂q of
    the phalanx's material point at p."""
    b = ref.R1 * ref.e(q[0])
    jb = np.column_stack([ref.R1 * ref.e_perp(q[0]), np.zeros(2), np.zeros(2)])
    psi = q[2] + ref.ALPHA
    tip = b + ref.L3 * ref.e(psi)
    out = []
    for obj in objects:
        shift, _ = motion_offset(obj, t)
        if obj["type"] == "circle":
            c, radius = np.array(obj["center"]) + shift, obj["radius"]
            for a, end, r, prox in ((np.zeros(2), b, rho[0], True), (b, tip, rho[1], False)):
                s = float(np.clip(np.dot(c - a, end - a) / np.dot(end - a, end - a), 0.0, 1.0))
                p = a + s * (end - a)
                dist = float(np.linalg.norm(p - c))
                n = (p - c) / dist
                if prox:
                    j = s * jb
                else:
                    j = jb + s * ref.L3 * np.column_stack([np.zeros(2), np.zeros(2), ref.e_perp(psi)])
                out.append((r + radius - dist, n, j))
        else:
            o, n = np.array(obj["point"]) + shift, np.array(obj["normal"], dtype=float)
            n = n / np.linalg.norm(n)
            jt = jb + ref.L3 * np.column_stack([np.zeros(2), np.zeros(2), ref.e_perp(psi)])
            for p, r, j in ((b, rho[0], jb), (b, rho[1], jb), (tip, rho[1], jt)):
                out.append((r - float(n @ (p - o)), n, j))
    return out


def _owners(objects) -> list[dict]:
    """The object of every candidate, in `_candidates`' order (a circle has two, a plane three)."""
    return [obj for obj in objects for _ in range(2 if obj["type"] == "circle" else 3)]


def contact_force(q, v, objects, law: ContactLaw, t: float = 0.0) -> np.ndarray:
    """Q_c = Σ J_pᵀ (F_n n + F_t t) over the candidates in contact (δ > 0), N·m; an object's own
    stiffness and damping replace the law's."""
    out = np.zeros(3)
    for (delta, n, j), obj in zip(_candidates(q, objects, law.rho, t), _owners(objects)):
        if delta <= 0.0:
            continue
        pv = j @ np.asarray(v) - motion_offset(obj, t)[1]
        k, d = obj.get("stiffness", law.k), obj.get("damping", law.d)
        fn = max(0.0, k * delta**law.e * (1.0 + d * (-float(n @ pv))))
        t = np.array([-n[1], n[0]])
        ft = -law.mu * fn * math.tanh(float(t @ pv) / law.vs)
        out += j.T @ (fn * n + ft * t)
    return out


def contact_energy(q, objects, law: ContactLaw) -> float:
    return sum(law.k * d ** (law.e + 1) / (law.e + 1) for d, _, _ in _candidates(q, objects, law.rho) if d > 0)


@dataclass
class HybridReference:
    """Dense pieces (t0, t1, sol or a held state) between events: `theta(t)` → (3, n)."""

    pieces: list
    impacts: int = 0

    def states(self, ts: np.ndarray) -> np.ndarray:
        out = np.empty((6, ts.size))
        starts = np.array([p[0] for p in self.pieces])
        idx = np.clip(np.searchsorted(starts, ts + 1e-13, side="right") - 1, 0, len(self.pieces) - 1)
        for i, s in enumerate(ts):
            t0, t1, sol = self.pieces[idx[i]]
            out[:, i] = sol(min(max(s, t0), t1)) if callable(sol) else sol
        return out


def solve(data: dict, *, rest_height: float = 1e-11, torque=None) -> HybridReference:
    """The reference of a scene mapping as written in config/ (the keys its hard scenes use); `torque`:
    (segment → τ(t), t_end → switches) in place of the scene's input (`ref.torque_from_dict`'s pair)."""
    model = data.get("model", {})
    fx = ref.Effects(k=model.get("spring_stiffness", ref.K_PAPER), c=model.get("damping", 0.0),
                     g=tuple(model.get("gravity", (0.0, 0.0))), f=tuple(model.get("tip_force", (0.0, 0.0))))
    c = model.get("contact", {})
    law = ContactLaw(c.get("stiffness", 1e5), c.get("exponent", 1.5), c.get("damping", 1.5), c.get("friction", 0.0),
                     c.get("slip_velocity", 1e-3), tuple(model.get("phalanx_radius", (0.008, 0.007))))
    objects = data.get("objects", [])
    limits = model.get("joint_limits", {}).get("mcp")
    e_stop = model.get("restitution", 0.0)
    on, switches = torque or ref.torque_from_dict(data["input"]["torque"])
    t_end = data["duration"]
    init = data.get("initial", {})
    q0 = ref.assemble(init.get("theta1", 0.0))
    y = np.concatenate([q0, ref.rates(q0, init.get("theta1_dot", 0.0))])
    edges = sorted({0.0, *[s for s in switches(t_end) if 0.0 < s < t_end], *motion_kinks(objects, t_end), t_end})
    out = HybridReference([])
    resting = False
    for a, b in zip(edges, edges[1:]):
        tau = on(a, b)

        def acc(t, y):
            q, v = y[:3], y[3:]
            qdd = kkt_with(q, v, tau(t), fx, contact_force(q, v, objects, law, t) if objects else np.zeros(3))
            return qdd

        def push(t, q, side):  # free acceleration of θ1 into the stop at rest (> 0: into it)
            return side * acc(t, np.concatenate([q, np.zeros(3)]))[0]

        t = a
        while t < b - 1e-15:
            if resting:
                q, side = y[:3], stop_side
                if push(t, q, side) >= 0.0:
                    tr = _release(lambda s: push(s, q, side), t, b)
                    out.pieces.append((t, tr, y.copy()))
                    t = tr
                    if tr >= b:  # held to the piece's end
                        continue
                resting = False
            events = []
            for i in range(len(_candidates(y[:3], objects, law.rho, t))):
                d0 = _candidates(y[:3], objects, law.rho, t)[i][0]
                side = 1.0 if d0 > ON_GAP else (-1.0 if d0 < -ON_GAP else (1.0 if _gap_rate(y, objects, law, i, t) > 0 else -1.0))
                f = (lambda s, yy, i=i, side=side: side * _candidates(yy[:3], objects, law.rho, s)[i][0])
                f.terminal, f.direction = True, -1
                events.append(f)
            if limits is not None:
                for lim, side in ((limits[0], -1.0), (limits[1], 1.0)):
                    f = (lambda s, yy, lim=lim, side=side: side * (lim - yy[0]))
                    f.terminal, f.direction = True, -1
                    events.append(f)
            rhs = lambda s, yy: np.concatenate([yy[3:], acc(s, yy)])  # noqa: E731
            sol = solve_ivp(rhs, (t, b), y, method="DOP853", rtol=RTOL, atol=ATOL, dense_output=True, events=events)
            assert sol.success, sol.message
            out.pieces.append((t, float(sol.t[-1]), sol.sol))
            t, y = float(sol.t[-1]), sol.y[:, -1].copy()
            # back onto Φ = 0, Φ_q q' = 0 at every restart (the index-1 equations drift between them)
            y[1:3] = ref._close(y[0], y[1:3])
            y[3:] = ref.rates(y[:3], y[3])
            n_contact = len(events) - (2 if limits is not None else 0)
            hit = [k for k in range(n_contact, len(events)) if sol.t_events[k].size]
            if sol.status == 1 and hit:
                stop_side = -1.0 if hit[0] == n_contact else 1.0
                y[0] = limits[0] if stop_side < 0 else limits[1]
                y[:3] = np.concatenate([[y[0]], ref._close(y[0], y[1:3])])
                out.impacts += 1
                v_plus = -e_stop * y[3:]
                closing = -push(t, y[:3], stop_side)  # θ1'' of the free finger at rest, away from the stop > 0
                if (closing < 0.0 and v_plus[0] ** 2 <= 2.0 * rest_height * abs(closing)) or (closing == 0.0 and v_plus[0] == 0.0):
                    # at rest: pushed into the stop, or on it with nothing pushing (then held until a push leaves)
                    y[3:] = 0.0
                    resting = True
                else:
                    y[3:] = v_plus
    return out


def _release(push, t0: float, t1: float) -> float:
    """The first time in [t0, t1] (s) where `push` (θ1'' into the stop at rest, ≥ 0 at t0) turns negative;
    t1 itself if it never does. A terminal event of solve_ivp on the push's integral: its steps follow
    the push's variation, so a release inside a long piece is located, not stepped over."""
    def event(s, z):
        return push(s) or math.ulp(0.0)  # held while ≥ 0: an exact 0 is on the holding side
    event.terminal, event.direction = True, -1
    sol = solve_ivp(lambda s, z: [push(s)], (t0, t1), [0.0], method="DOP853", rtol=RTOL, atol=ATOL, events=event)
    assert sol.success, sol.message
    return float(sol.t_events[0][0]) if sol.t_events[0].size else t1


def kkt_with(q, v, tau: float, fx: ref.Effects, extra: np.ndarray) -> np.ndarray:
    """q'' of spec §4 by the dense 5×5 solve, with the generalized force `extra` (N·m) added to Q."""
    a = np.zeros((5, 5))
    a[:3, :3] = ref.mass(q)
    g = ref.phi_q(q)
    a[:3, 3:] = -g.T
    a[3:, :3] = g
    rhs = np.concatenate([fx.force(q, v, tau) + extra - ref.coriolis(q, v), ref.gamma(q, v)])
    return np.linalg.solve(a, rhs)[:3]


def _gap_rate(y, objects, law, i, t: float = 0.0) -> float:
    d, n, j = _candidates(y[:3], objects, law.rho, t)[i]
    return -float(n @ (j @ y[3:] - motion_offset(_owners(objects)[i], t)[1]))
