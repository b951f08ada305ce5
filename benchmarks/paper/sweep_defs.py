"""The sweeps: the points of the paper's Figs. 3-10 (section 4), two variants with the fence
length fixed, and the controller's decision table, each with its plot panels."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from benchmarks.paper.decision import decision_points
from benchmarks.paper.points import point
from benchmarks.paper.sweep_rows import solve_point

G = 9.81


def free_fall_speed(height: float) -> float:
    """Impact speed of a free fall from ``height`` [m], to 0.1 m/s as the paper rounds it
    (w_dop = 2.4 m/s for 0.3 m, section 3)."""
    return round(math.sqrt(2.0 * G * height), 1)


#: alpha_k of Figs. 3, 6, 7 [deg] (section 4.2: 20..60 in steps of 5)
ALPHAS_DEG = tuple(float(a) for a in range(20, 61, 5))
#: w_dop levels of Figs. 3 and 5: free falls from 0.1, 0.2, 0.3 (the paper's), 0.5 m
W_DOP_LEVELS = tuple(free_fall_speed(h) for h in (0.1, 0.2, 0.3, 0.5))
#: a_Ndop levels of Figs. 6-10 [m/s^2]: 15 (the paper's "small", ~1.5 g) ... 300 (~30 g)
A_NDOP_LEVELS = (15.0, 50.0, 150.0, 300.0)
#: load lengths A of Figs. 5, 8-10 [m] (the paper names 0.1 and 1.2)
LENGTHS = (0.1, 0.3, 0.5, 0.7, 0.9, 1.2)


# -- sweep definitions --------------------------------------------------------------------------
@dataclass(frozen=True)
class Panel:
    column: str
    label: str
    scale: float = 1.0  # plotted value = column * scale


@dataclass(frozen=True)
class SweepDef:
    """One figure: the points of its run and how to plot them."""

    name: str
    figure: str
    title: str
    run: str  # the CSV (run) that holds its points: fig9 plots fig8's run
    points: tuple[dict, ...]
    x: str  # column on the abscissa
    x_label: str
    series: str  # one curve per value of this column
    series_label: str
    panels: tuple[Panel, ...]
    solve: Callable[[Mapping], dict] = field(default=solve_point, compare=False)
    note: str = ""


P_T1 = Panel("t1", "t1 [s]")
P_WT = Panel("W_t", "W_t [pcs/h]")
P_RS = Panel("R_s", "R_s [m]")
P_V = Panel("v", "v [m/s]")
P_RZ = Panel("R_z", "R_z [m]")
P_DELTA = Panel("Delta", "required distance Delta [m]")
P_EXIT = Panel("exit_speed", "exit speed ydot [m/s]")
P_ACC = Panel("accel", "a_N [m/s^2]")

C_ARB = "7 8 9 10"
C_POS = "7 8 11"
C_POS12 = "7 8 11 12"


def _fig3() -> tuple[dict, ...]:
    return tuple(
        point(case="arbitrary", alpha_k_deg=a, w_dop=w, constraints=C_ARB)
        for w in W_DOP_LEVELS
        for a in ALPHAS_DEG
    )


def _fig4() -> tuple[dict, ...]:
    return tuple(
        point(
            case="arbitrary",
            alpha_k_deg=40.0,
            w_dop=2.4,
            constraints=C_ARB,
            mu1=m1,
            mu2=m2,
            fixed="R_s=0.0 R_z=1.4",
        )
        for m2 in (0.2, 0.35, 0.5)
        for m1 in (0.35, 0.5, 0.65, 0.8)
    )


def _fig5() -> tuple[dict, ...]:
    return tuple(
        point(case="arbitrary", alpha_k_deg=40.0, w_dop=w, constraints=C_ARB, load_length=a)
        for w in W_DOP_LEVELS[1:]
        for a in LENGTHS
    )


def _fig6(constraints: str) -> tuple[dict, ...]:
    return tuple(
        point(case="positioned", alpha_k_deg=a, a_ndop=an, constraints=constraints)
        for an in A_NDOP_LEVELS
        for a in ALPHAS_DEG
    )


def _fig8(constraints: str, fixed: str = "") -> tuple[dict, ...]:
    return tuple(
        point(
            case="positioned",
            alpha_k_deg=40.0,
            a_ndop=an,
            constraints=constraints,
            load_length=a,
            fixed=fixed,
        )
        for an in A_NDOP_LEVELS
        for a in LENGTHS
    )


#: the extra sweeps' fence: the 1.2 m of section 4.3 (R_z does not enter W_t (1), so with it
#: free the optimiser may shorten the fence until (12) holds at any stroke speed)
FIXED_RZ = "R_z=1.2"


def _fig7_fixed_rz() -> tuple[dict, ...]:
    return tuple(
        point(case="positioned", alpha_k_deg=a, a_ndop=an, constraints=C_POS12, fixed=FIXED_RZ)
        for an in A_NDOP_LEVELS[1:]
        for a in ALPHAS_DEG
    )


def _decision_points() -> tuple[dict, ...]:
    return decision_points()


def _defs() -> dict[str, SweepDef]:
    alpha = ("alpha_k_deg", "alpha_k [deg]")
    length = ("load_length", "load length A [m]")
    a_ndop = ("a_ndop", "a_Ndop [m/s^2]")
    fig8_points = ("fig8", _fig8(C_POS))  # Fig. 9 is drawn from the optima of Fig. 8
    defs = [
        SweepDef(
            "fig3",
            "Fig. 3",
            "arbitrary placement, (7)-(10): parameters vs alpha_k and w_dop",
            "fig3",
            _fig3(),
            *alpha,
            "w_dop",
            "w_dop [m/s]",
            (P_T1, P_WT, P_RS, P_V, P_RZ, P_DELTA),
        ),
        SweepDef(
            "fig4",
            "Fig. 4",
            "arbitrary placement, (7)-(10), alpha_k 40 deg, R_s 0, R_z 1.4 m: vs mu1, mu2",
            "fig4",
            _fig4(),
            "mu1",
            "mu1 (belt)",
            "mu2",
            "mu2 (fence)",
            (P_T1, P_WT, P_V),
        ),
        SweepDef(
            "fig5",
            "Fig. 5",
            "arbitrary placement, (7)-(10), alpha_k 40 deg, B 0.1 m: vs load length A and w_dop",
            "fig5",
            _fig5(),
            *length,
            "w_dop",
            "w_dop [m/s]",
            (P_WT, P_RS, P_RZ),
        ),
        SweepDef(
            "fig6",
            "Fig. 6",
            "positioned, (7), (8), (11): parameters vs alpha_k and a_Ndop",
            "fig6",
            _fig6(C_POS),
            *alpha,
            *a_ndop,
            (P_T1, P_WT, P_RS, P_V, P_RZ, P_EXIT),
        ),
        SweepDef(
            "fig7",
            "Fig. 7",
            "positioned, (7), (8), (11) and (12): vs alpha_k and a_Ndop",
            "fig7",
            _fig6(C_POS12),
            *alpha,
            *a_ndop,
            (P_T1, P_WT, P_ACC),
        ),
        SweepDef(
            "fig8",
            "Fig. 8",
            "positioned, (7), (8), (11), alpha_k 40 deg, B 0.1 m: vs load length A and a_Ndop",
            *fig8_points,
            *length,
            *a_ndop,
            (P_T1, P_WT, P_RS),
        ),
        SweepDef(
            "fig9",
            "Fig. 9",
            "exit speed towards the chute of the Fig. 8 optima (worst centre of gravity)",
            *fig8_points,
            *length,
            *a_ndop,
            (P_EXIT,),
        ),
        SweepDef(
            "fig10",
            "Fig. 10",
            "positioned, (7), (8), (11) and (12), alpha_k 40 deg: vs load length A and a_Ndop",
            "fig10",
            _fig8(C_POS12),
            *length,
            *a_ndop,
            (P_T1, P_WT, P_V),
        ),
    ]
    defs += [
        SweepDef(
            "fig7-fixed-rz",
            "Fig. 7 (R_z = 1.2 m)",
            "as Fig. 7 with the fence length held at 1.2 m (section 4.3)",
            "fig7-fixed-rz",
            _fig7_fixed_rz(),
            *alpha,
            *a_ndop,
            (P_T1, P_WT, P_ACC, P_RS, P_V, P_EXIT),
        ),
        SweepDef(
            "fig10-fixed-rz",
            "Fig. 10 (R_z = 1.2 m)",
            "as Fig. 10 with the fence length held at 1.2 m (section 4.3)",
            "fig10-fixed-rz",
            _fig8(C_POS12, FIXED_RZ),
            *length,
            *a_ndop,
            (P_T1, P_WT, P_V, P_ACC, P_RS, P_EXIT),
        ),
    ]
    return {d.name: d for d in defs}


#: the paper's figures (``paper-sweep all``)
PAPER_SWEEPS: tuple[str, ...] = tuple(f"fig{i}" for i in range(3, 11))
#: names accepted by paper-sweep: the paper's figures, two variants with the fence length fixed,
#: and the controller's starting candidates
SWEEPS: tuple[str, ...] = (*PAPER_SWEEPS, "fig7-fixed-rz", "fig10-fixed-rz", "decision-table")


def get_sweep(name: str) -> SweepDef:
    """The definition of sweep ``name`` (KeyError naming the allowed names)."""
    if name == "decision-table":
        return SweepDef(
            "decision-table",
            "Decision table",
            "the controller's starting candidates, R_s and t1 per load class at the "
            "configured alpha_k and belt speed",
            "decision-table",
            _decision_points(),
            "load_length",
            "load length A [m]",
            "case",
            "placement",
            (P_T1, P_RS, P_WT),
        )
    defs = _defs()
    if name not in defs:
        raise KeyError(f"unknown sweep {name!r}; allowed: {', '.join(SWEEPS)}, all")
    return defs[name]
