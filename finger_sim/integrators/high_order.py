"""Higher-order fixed-step explicit Runge-Kutta methods: sixth and eighth order, as tableaus.

For smooth scenes a higher order buys accuracy cheaply: at dt = 1 ms RK4 is off by 7.5e-6
rad where the linkage passes its toggle (θ3' ≈ 34 rad/s), Butcher's sixth-order method by
9e-9 rad at 1.7× RK4's cost per step, and the eighth-order Dormand-Prince solution by
4e-12 rad at 3×; at large dt the eighth order reaches 1e-8 rad in a handful of steps
(docs/performance.md has the measurements). Both are data for `ExplicitRungeKutta`.
"""

from __future__ import annotations

from finger_sim.integrators.explicit import ExplicitRungeKutta


class ButcherRK6(ExplicitRungeKutta):
    """Butcher's seven-stage sixth-order Runge-Kutta, projected: order 6, Φ = 0 to round-off; the smooth real-time default.

    J. C. Butcher, "On Runge-Kutta processes of high order", J. Austral. Math. Soc. 4
    (1964) 179-194; seven stages is the least a sixth order needs. Cost: 7 acceleration
    solves + 1 projection per step (about 1.7× RK4's step). Stable for |λ|dt up to ≈ 1.08
    on the oscillatory axis and ≈ 2.86 on the real one (`is_stable`, from the tableau,
    with STABILITY_SLACK): an undamped mode needs at least ~6 steps per period.
    """

    name = "rk6"
    order = 6
    C = (0.0, 1 / 3, 2 / 3, 1 / 3, 1 / 2, 1 / 2, 1.0)
    A = (
        (),
        (1 / 3,),
        (0.0, 2 / 3),
        (1 / 12, 1 / 3, -1 / 12),
        (-1 / 16, 9 / 8, -3 / 16, -3 / 8),
        (0.0, 9 / 8, -3 / 8, -3 / 4, 1 / 2),
        (9 / 44, -9 / 11, 63 / 44, 18 / 11, 0.0, -16 / 11),
    )
    B = (11 / 120, 0.0, 27 / 40, 27 / 40, -4 / 15, -4 / 15, 11 / 120)


class DormandPrince8(ExplicitRungeKutta):
    """Dormand-Prince 8 at a fixed step, projected: order 8, Φ = 0 to round-off; for smooth scenes at large dt.

    The 12-stage eighth-order solution of DOP853 (Hairer, Nørsett & Wanner, *Solving ODEs I*,
    §II.10; coefficients as in Hairer's dop853.f and scipy's `dop853_coefficients`), used
    without its error estimator: a fixed step on the index-1 equations, then the projection
    onto Φ = 0, Φ_q q' = 0 that every `ExplicitRungeKutta` applies.
    Cost: 12 acceleration solves + 1 projection per step (about 4× RK4's step).
    Stable for |λ|dt up to ≈ 5.96 on the oscillatory axis and ≈ 6.4 on the real one
    (`is_stable`, from the tableau): like RK4, refused on stiff scenes.
    """

    name = "dop8"
    order = 8
    C = (
        0.0,
        0.05260015195876773,
        0.0789002279381516,
        0.1183503419072274,
        0.2816496580927726,
        0.3333333333333333,
        0.25,
        0.3076923076923077,
        0.6512820512820513,
        0.6,
        0.8571428571428571,
        1.0,
    )
    A = (
        (),
        (0.05260015195876773,),
        (0.0197250569845379, 0.0591751709536137),
        (0.02958758547680685, 0.0, 0.08876275643042054),
        (0.2413651341592667, 0.0, -0.8845494793282861, 0.924834003261792),
        (0.037037037037037035, 0.0, 0.0, 0.17082860872947386, 0.12546768756682242),
        (0.037109375, 0.0, 0.0, 0.17025221101954405, 0.06021653898045596, -0.017578125),
        (
            0.03709200011850479, 0.0, 0.0, 0.17038392571223998, 0.10726203044637328,
            -0.015319437748624402, 0.008273789163814023,
        ),
        (
            0.6241109587160757, 0.0, 0.0, -3.3608926294469414, -0.868219346841726,
            27.59209969944671, 20.154067550477894, -43.48988418106996,
        ),
        (
            0.47766253643826434, 0.0, 0.0, -2.4881146199716677, -0.590290826836843,
            21.230051448181193, 15.279233632882423, -33.28821096898486, -0.020331201708508627,
        ),
        (
            -0.9371424300859873, 0.0, 0.0, 5.186372428844064, 1.0914373489967295, -8.149787010746927,
            -18.52006565999696, 22.739487099350505, 2.4936055526796523, -3.0467644718982196,
        ),
        (
            2.273310147516538, 0.0, 0.0, -10.53449546673725, -2.0008720582248625, -17.9589318631188,
            27.94888452941996, -2.8589982771350235, -8.87285693353063, 12.360567175794303, 0.6433927460157636,
        ),
    )
    B = (
        0.054293734116568765, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003,
        -5.801203960010585, 0.3111643669578199, -0.1521609496625161, 0.20136540080403034,
        0.04471061572777259,
    )
