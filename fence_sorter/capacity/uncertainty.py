"""The set of loads a scanned parcel may be, and the corners of it a stroke is verified at.

The scanner's figures are not exact: mass within ``mass`` (relative), the friction
coefficients mu1 (belt) and mu2 (fence) within ``mu`` (absolute), the sizes A and B within
``size`` [m]. A stroke counts as feasible only if (7)-(12) hold at the nominal load and at the
corners of that box that drive each limit. The corners were found by the main effects of each
factor on the flexible fence of the default scene at 2 m/s (docs/guide/controller.md):

- a_N (11) rises for a lighter load, higher mu1 and mu2, smaller A and larger B;
- the exit speed (12) rises for lower mu2 (by far the largest effect, up to ~1 m/s over
  +-0.05), lower mu1, larger B and smaller A; the mass acts either way;
- (8) (y_k and the crossing speed at y0 = s) gets worse for higher mu1 and mu2 and a heavier,
  longer, narrower load; (10) w_n rises with A (by mm/s: kinematic); (9) worsens with
  smaller A.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from fence_sorter.physics.params import ParcelParams, check_range


@dataclass(frozen=True)
class Corner:
    """One corner of the uncertainty box: signs (-1, 0, +1) of each factor's deviation."""

    name: str
    mass: int
    mu_belt: int
    mu_fence: int
    length_a: int
    width_b: int
    drives: tuple[int, ...]  # the constraints this corner bounds


#: the corners checked besides the nominal load, and the limits each one bounds
CORNERS = (
    Corner("slippery heavy", +1, -1, -1, -1, +1, (12, 9)),
    Corner("slippery light", -1, -1, -1, -1, +1, (12,)),
    Corner("grippy light", -1, +1, +1, -1, +1, (11,)),
    Corner("grippy heavy long", +1, +1, +1, +1, -1, (8, 10)),
)


@dataclass(frozen=True)
class UncertaintySet:
    """Half-widths of the box around the scanned load (0: that figure is exact)."""

    mass: float = 0.05  # relative
    mu: float = 0.05  # absolute, mu1 and mu2
    size: float = 0.005  # [m], A and B

    def validate(self, prefix: str = "controller") -> UncertaintySet:
        check_range(f"{prefix}.uncertainty_mass", self.mass, 0.0, 0.5)
        check_range(f"{prefix}.uncertainty_mu", self.mu, 0.0, 0.5)
        check_range(f"{prefix}.uncertainty_size", self.size, 0.0, 0.1, unit="m")
        return self

    def corners(self) -> tuple[Corner, ...]:
        """The corners to check: none when every half-width is 0; a factor with zero
        half-width does not split corners that differ only in it."""
        if self.mass == 0.0 and self.mu == 0.0 and self.size == 0.0:
            return ()
        out: list[Corner] = []
        seen: set[tuple[int, ...]] = set()
        for c in CORNERS:
            sig = (
                c.mass if self.mass else 0,
                c.mu_belt if self.mu else 0,
                c.mu_fence if self.mu else 0,
                c.length_a if self.size else 0,
                c.width_b if self.size else 0,
            )
            if sig not in seen:
                seen.add(sig)
                out.append(c)
        return tuple(out)

    def apply(
        self, corner: Corner, parcel: ParcelParams, mu1: float, mu2: float, belt_width: float
    ) -> tuple[ParcelParams, float, float]:
        """(load, mu1, mu2) at ``corner``; a wider load keeps its side off the fence and is
        moved towards it only as far as it must to stay on the belt."""
        a = max(parcel.length_a + corner.length_a * self.size, 0.005)
        b = max(parcel.width_b + corner.width_b * self.size, 0.005)
        p = replace(
            parcel,
            mass=parcel.mass * (1.0 + corner.mass * self.mass),
            length_a=a,
            width_b=b,
            cog_offset_x=max(-0.5 * a, min(0.5 * a, parcel.cog_offset_x)),
            cog_offset_y=max(-0.5 * b, min(0.5 * b, parcel.cog_offset_y)),
        )
        room = belt_width - p.footprint_width()
        if p.lateral_gap > room:
            p = replace(p, lateral_gap=max(room, 0.0))
        m1 = max(mu1 + corner.mu_belt * self.mu, 0.0)
        m2 = max(mu2 + corner.mu_fence * self.mu, 0.0)
        return p, m1, m2
