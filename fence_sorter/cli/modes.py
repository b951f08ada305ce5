"""``fence-sorter modes SCENE``: natural frequencies and static tip deflection of the fence.

For the flexible fence of a scene: the first N clamped-free natural frequencies of the FEM beam
and its static tip deflection under a tip load P, with the closed form to compare against,
(2/3) P R_z^3 / (E I1) for the constant-strength taper or P L^3 / (3 E I) for a uniform beam
(I1 = z h1^3 / 12). Exit 2 on a bad scene or a stiff fence.
"""

from __future__ import annotations

import argparse
import json

from fence_sorter.cli.simulate import EXIT_OK, add_scene_arguments, error, load


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = "Natural frequencies and static tip deflection of the flexible fence."
    add_scene_arguments(parser)
    parser.add_argument(
        "--tip-load",
        type=float,
        default=100.0,
        metavar="P",
        help="static tip load [N] (default 100)",
    )
    parser.add_argument(
        "--count", type=int, default=5, metavar="N", help="number of modes (default 5)"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.set_defaults(func=run)


def closed_form_tip_deflection(fence, tip_load: float) -> float:
    """(2/3) P R_z^3 / (E I1) for constant_strength, P L^3 / (3 E I) for uniform."""
    inertia = fence.height * fence.root_thickness**3 / 12.0
    factor = 2.0 / 3.0 if fence.profile == "constant_strength" else 1.0 / 3.0
    return factor * tip_load * fence.length**3 / (fence.youngs_modulus * inertia)


def run(args: argparse.Namespace) -> int:
    loaded, code = load(args)
    if loaded is None:
        return code
    fence = loaded.scenario.fence
    if fence is None:
        return error(
            f"scene {loaded.source_path.name}: modes needs a flexible fence (fence.type: flexible)"
        )
    # lazy: loads SciPy
    from fence_sorter.physics.fence import build_fence, natural_frequencies, static_tip_deflection

    model = build_fence(fence)
    if not 1 <= args.count <= model.n_dof:
        return error(
            f"--count must be in [1, {model.n_dof}] (2 x fence.elements), got {args.count}"
        )
    freqs = [float(f) for f in natural_frequencies(model, args.count)]
    tip = static_tip_deflection(model, args.tip_load)
    closed = closed_form_tip_deflection(fence, args.tip_load)
    out = {
        "scene": loaded.name,
        "profile": fence.profile,
        "elements": int(fence.elements),
        "mass_kg": model.mass(),
        "frequencies_hz": freqs,
        "tip_load_N": args.tip_load,
        "tip_deflection_m": tip,
        "closed_form_tip_deflection_m": closed,
        "warnings": list(loaded.warnings),
    }
    if args.json:
        print(json.dumps(out))
        return EXIT_OK
    print(f"scene          {loaded.name}")
    print(
        f"fence          {fence.profile}, R_z = {fence.length:g} m, {fence.elements} elements, "
        f"mass {out['mass_kg']:.3f} kg"
    )
    for i, f in enumerate(freqs, start=1):
        print(f"mode {i:<9d} {f:10.3f} Hz")
    dev = (tip / closed - 1.0) * 100.0 if closed else float("nan")
    print(
        f"tip deflection {tip * 1e3:.4f} mm under P = {args.tip_load:g} N "
        f"(closed form {closed * 1e3:.4f} mm, {dev:+.2f} %)"
    )
    return EXIT_OK
