"""The kernel's explicit Runge–Kutta steps, one per state width and stage function.

Generated from one template by `python -m finger_sim.kernel.rk_template`: do not edit.
"""


def rk_step(m, tab, t, x, h, taus, k):
    """One projected explicit RK step on x = (q, q') in place: `ExplicitRungeKutta.step`. Status.

    tab: (s + 3) × s tableau (A, B, C rows, then each stage's node index; `layout.tableau_array`);
    taus: the input at each distinct node time t + c h; k: s × 6 work array of stage derivatives.
    Zero tableau entries are skipped, as in Python. `accelerations` and `project`: bound where it is compiled.
    """
    s = tab.shape[1]
    for i in range(s):
        x0, x1, x2, w0, w1, w2 = x[0], x[1], x[2], x[3], x[4], x[5]
        for j in range(i):
            a = tab[i, j]
            if a != 0.0:
                ha = h * a
                x0 += ha * k[j, 0]
                x1 += ha * k[j, 1]
                x2 += ha * k[j, 2]
                w0 += ha * k[j, 3]
                w1 += ha * k[j, 4]
                w2 += ha * k[j, 5]
        k[i, 0], k[i, 1], k[i, 2] = w0, w1, w2
        tau = taus[int(tab[s + 2, i])]
        k[i, 3], k[i, 4], k[i, 5] = accelerations(m, t + tab[s + 1, i] * h, x0, x1, x2, w0, w1, w2, tau)
    for j in range(s):
        b = tab[s, j]
        if b != 0.0:
            hb = h * b
            for c in range(6):
                x[c] += hb * k[j, c]
    return project(m, x)


def inductive_rk_step(m, tab, t, x, h, taus, k):
    """One projected explicit RK step on x = (q, q', i) in place: `StatefulRungeKutta._substep`. Status.

    tab: (s + 3) × s tableau (A, B, C rows, then each stage's node index; `layout.tableau_array`);
    taus: the input at each distinct node time t + c h; k: s × 7 work array of stage derivatives.
    Zero tableau entries are skipped, as in Python. `inductive_rates` and `project`: bound where it is compiled.
    """
    s = tab.shape[1]
    for i in range(s):
        x0, x1, x2, w0, w1, w2, x6 = x[0], x[1], x[2], x[3], x[4], x[5], x[6]
        for j in range(i):
            a = tab[i, j]
            if a != 0.0:
                ha = h * a
                x0 += ha * k[j, 0]
                x1 += ha * k[j, 1]
                x2 += ha * k[j, 2]
                w0 += ha * k[j, 3]
                w1 += ha * k[j, 4]
                w2 += ha * k[j, 5]
                x6 += ha * k[j, 6]
        k[i, 0], k[i, 1], k[i, 2] = w0, w1, w2
        tau = taus[int(tab[s + 2, i])]
        k[i, 3], k[i, 4], k[i, 5], k[i, 6] = inductive_rates(m, t + tab[s + 1, i] * h, x0, x1, x2, w0, w1, w2, tau, x6)
    for j in range(s):
        b = tab[s, j]
        if b != 0.0:
            hb = h * b
            for c in range(7):
                x[c] += hb * k[j, c]
    return project(m, x)
