"""An independent reference for stick–slip friction at fixed objects (spec §7), for test_stick_slip.

Nothing here imports finger_sim. The dynamics are test/reference.py's (rigid-body mass matrix,
dense 5×5 KKT solve), the contact candidates and Jacobians hybrid_reference.py's; the friction law
is spec §7 written again:
- sliding towards s = ±1: F_t,k = −μ F_n,k sgn(j_k s), μ = μ_k or with a Stribeck velocity
  μ_k + (μ_s − μ_k) exp(−(j_k θ1'/v_st)²), j_k = t_k·J_k n (n = ∂q/∂θ1 on Φ = 0), each
  smooth piece integrated by scipy's DOP853 at rtol 1e-11, stopped at θ1' = 0 (a terminal event) and
  at every contact onset or release and torque switch;
- locked: statics. The holding torque τ_h is what keeps θ1'' = 0 at q' = 0 (two KKT solves: θ1'' is
  affine in the torque on θ1); the linkage holds while |τ_h| ≤ Σ μ_s F_n,k |j_k|, and breaks free at the
  root of that margin in time (brentq), towards −sgn τ_h.
No joint stops, no moving objects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

import reference as ref
from hybrid_reference import _candidates, kkt_with

RTOL, ATOL = 1e-11, 1e-13
#: A contact gap this close to zero counts as on it when choosing its side at a restart.
ON_GAP = 1e-13
#: A tangential gain |j_k| this small (m/rad) at a restart is the zero the piece starts on (slip_zeros).
ON_GAIN = 1e-10


@dataclass(frozen=True)
class Law:
    k: float = 1e5  # N/m^e
    e: float = 1.5
    d: float = 1.5  # s/m
    mu_k: float = 0.0
    mu_s: float = 0.0
    v_st: float | None = None  # m/s, the Stribeck velocity (None: none)
    rho: tuple[float, float] = (0.008, 0.007)  # m


def contacts(q, v, objects, law: Law):
    """(F_n, n, t, J, j_k) of every candidate in contact: F_n with Hunt–Crossley damping at q'."""
    along = ref.rates(q, 1.0)
    out = []
    for delta, n, j in _candidates(q, objects, law.rho):
        if delta <= 0.0:
            continue
        fn = max(0.0, law.k * delta**law.e * (1.0 - law.d * float(n @ (j @ np.asarray(v)))))
        t = np.array([-n[1], n[0]])
        out.append((fn, n, t, j, float(t @ (j @ along))))
    return out


def sliding_force(q, v, s: float, objects, law: Law) -> np.ndarray:
    """Q_c = Σ J_kᵀ (F_n n − μ F_n sgn(j_k s) t), N·m: μ = μ_k, or μ_k + (μ_s − μ_k) exp(−(j_k θ1'/v_st)²)."""
    out = np.zeros(3)
    for fn, n, t, j, jk in contacts(q, v, objects, law):
        mu = law.mu_k if law.v_st is None else law.mu_k + (law.mu_s - law.mu_k) * math.exp(-(jk * v[0] / law.v_st) ** 2)
        out += j.T @ (fn * n - mu * fn * np.sign(jk * s) * t)
    return out


def holding(q, tau: float, fx: ref.Effects, objects, law: Law) -> tuple[float, float]:
    """(τ_h N·m, Σ μ_s F_n |j_k| N·m) at rest at q under the motor torque τ."""
    zero = np.zeros(3)
    normal = sum((j.T @ (fn * n) for fn, n, _, j, _ in contacts(q, zero, objects, law)), np.zeros(3))
    a0 = kkt_with(q, zero, tau, fx, normal)[0]
    a1 = kkt_with(q, zero, tau + 1.0, fx, normal)[0]
    capacity = sum(law.mu_s * fn * abs(jk) for fn, _, _, _, jk in contacts(q, zero, objects, law))
    return -a0 / (a1 - a0), capacity


@dataclass
class StickSlipReference:
    """Pieces (t0, t1, dense solution or a held state) and the mode changes (t, "lock" | "break")."""

    pieces: list = field(default_factory=list)
    changes: list = field(default_factory=list)

    def states(self, ts: np.ndarray) -> np.ndarray:
        out = np.empty((6, ts.size))
        starts = np.array([p[0] for p in self.pieces])
        idx = np.clip(np.searchsorted(starts, ts + 1e-13, side="right") - 1, 0, len(self.pieces) - 1)
        for i, s in enumerate(ts):
            t0, t1, sol = self.pieces[idx[i]]
            out[:, i] = sol(min(max(s, t0), t1)) if callable(sol) else sol
        return out


def solve(data: dict, *, slip_zeros: bool = False, torque=None) -> StickSlipReference:
    """The reference of a scene mapping (the keys test_stick_slip's scenes use). slip_zeros: also restart
    the sliding pieces where a candidate's j_k changes sign (its friction flips, spec §7), so that no
    piece straddles that kink of the force along the linkage. torque: (segment → τ(t), t_end → switches)
    in place of the scene's input (`ref.torque_from_dict`'s pair)."""
    model = data.get("model", {})
    fx = ref.Effects(k=model.get("spring_stiffness", ref.K_PAPER), c=model.get("damping", 0.0),
                     g=tuple(model.get("gravity", (0.0, 0.0))), f=tuple(model.get("tip_force", (0.0, 0.0))))
    c = model.get("contact", {})
    mu_k = c.get("friction", 0.0)
    law = Law(c.get("stiffness", 1e5), c.get("exponent", 1.5), c.get("damping", 1.5), mu_k,
              c.get("static_friction", mu_k), c.get("stribeck_velocity"), tuple(model.get("phalanx_radius", (0.008, 0.007))))
    objects = data.get("objects", [])
    on, switches = torque or ref.torque_from_dict(data["input"]["torque"])
    t_end = data["duration"]
    init = data.get("initial", {})
    q0 = ref.assemble(init.get("theta1", 0.0))
    y = np.concatenate([q0, ref.rates(q0, init.get("theta1_dot", 0.0))])
    edges = [0.0, *[s for s in switches(t_end) if 0.0 < s < t_end], t_end]
    out = StickSlipReference()

    def turn(t: float, q, tau) -> tuple[bool, float]:
        """The holding test at a turning point: (locked, sliding direction)."""
        tau_h, capacity = holding(q, tau(t), fx, objects, law)
        return (capacity - abs(tau_h) >= 0.0), -math.copysign(1.0, tau_h)

    locked, s = turn(0.0, q0, on(0.0, edges[1])) if y[3] == 0.0 else (False, math.copysign(1.0, y[3]))
    for a, b in zip(edges, edges[1:]):
        tau = on(a, b)
        t = a
        while t < b - 1e-15:
            if locked:
                q = y[:3].copy()

                def margin(x):
                    tau_h, capacity = holding(q, tau(x), fx, objects, law)
                    return capacity - abs(tau_h)

                if margin(t) >= 0.0 and margin(b) >= 0.0:
                    out.pieces.append((t, b, y.copy()))
                    t = b
                    continue
                tb = t if margin(t) < 0.0 else brentq(margin, t, b, xtol=1e-15, rtol=4 * np.finfo(float).eps)
                out.pieces.append((t, tb, y.copy()))
                out.changes.append((tb, "break"))
                t, locked = tb, False
                s = -math.copysign(1.0, holding(q, tau(tb), fx, objects, law)[0])

            def rhs(x, yy, s=s):
                q, v = yy[:3], yy[3:]
                return np.concatenate([v, kkt_with(q, v, tau(x), fx, sliding_force(q, v, s, objects, law))])

            stop = (lambda x, yy, s=s: s * yy[3])
            stop.terminal, stop.direction = True, -1
            events = [stop]
            for i in range(len(_candidates(y[:3], objects, law.rho))):
                d0, n, j = _candidates(y[:3], objects, law.rho)[i]
                rate = -float(n @ (j @ y[3:]))
                side = 1.0 if d0 > ON_GAP else (-1.0 if d0 < -ON_GAP else (1.0 if rate > 0 else -1.0))
                f = (lambda x, yy, i=i, side=side: side * _candidates(yy[:3], objects, law.rho)[i][0])
                f.terminal, f.direction = True, -1
                events.append(f)
            if slip_zeros:
                along = (lambda yy: ref.rates(yy[:3], 1.0))

                def gain(yy, i):  # j_k = t_k·J_k n
                    _, n, j = _candidates(yy[:3], objects, law.rho)[i]
                    return float(np.array([-n[1], n[0]]) @ (j @ along(yy)))

                for i in range(len(_candidates(y[:3], objects, law.rho))):
                    if abs(gain(y, i)) > ON_GAIN:  # not the zero this piece starts on
                        f = (lambda x, yy, i=i: gain(yy, i))
                        f.terminal = True
                        events.append(f)
            sol = solve_ivp(rhs, (t, b), y, method="DOP853", rtol=RTOL, atol=ATOL, dense_output=True, events=events)
            assert sol.success, sol.message
            out.pieces.append((t, float(sol.t[-1]), sol.sol))
            t, y = float(sol.t[-1]), sol.y[:, -1].copy()
            y[1:3] = ref._close(y[0], y[1:3])  # back onto Φ = 0, Φ_q q' = 0 at every restart
            y[3:] = ref.rates(y[:3], y[3])
            if sol.status == 1 and sol.t_events[0].size:  # θ1' = 0: the holding test
                y[3:] = 0.0
                locked, s = turn(t, y[:3], tau)
                if locked:
                    out.changes.append((t, "lock"))
    return out
