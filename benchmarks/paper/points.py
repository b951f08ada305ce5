"""One point of a sweep: the inputs of one optimisation (one optimum (1)), with the paper's
section 3 values as defaults; the CSV columns of :mod:`benchmarks.paper.sweep` start with
them."""

from __future__ import annotations

#: the inputs of one point (one optimisation), scalar columns of the CSV; SI but alpha_k in deg
INPUT_COLUMNS: dict[str, type] = {
    "case": str,  # arbitrary | positioned
    "alpha_k_deg": float,
    "w_dop": float,
    "a_ndop": float,
    "exit_speed_limit": float,
    "constraints": str,  # "7 8 11"
    "mu1": float,
    "mu2": float,
    "load_length": float,
    "load_width": float,
    "fixed": str,  # "R_s=0 R_z=1.4" (empty: none)
    "bounds": str,  # "R_s=-0.4:1 t1=0.2:1.5" (empty: the ranges (3)-(6))
    "budget": int,  # 0: the optimiser's default
}

DEFAULT_INPUTS: dict = {
    "case": "positioned",
    "alpha_k_deg": 40.0,
    "w_dop": 2.4,
    "a_ndop": 300.0,
    "exit_speed_limit": 2.5,
    "constraints": "7 8 9 10",
    "mu1": 0.65,
    "mu2": 0.35,
    "load_length": 0.7,
    "load_width": 0.1,
    "fixed": "",
    "bounds": "",
    "budget": 0,
}


def point(**kw) -> dict:
    """The inputs of one point: the defaults (paper section 3 values) updated by ``kw``."""
    unknown = set(kw) - set(INPUT_COLUMNS)
    if unknown:
        raise KeyError(f"unknown point input(s) {sorted(unknown)}; allowed: {list(INPUT_COLUMNS)}")
    out = dict(DEFAULT_INPUTS)
    out.update(kw)
    return {k: INPUT_COLUMNS[k](v) for k, v in out.items()}
