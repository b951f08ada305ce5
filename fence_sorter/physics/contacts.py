"""Motion stages E1-E4 from the active contact set (paper section 2, appendix).

The contacts themselves are evaluated in ``kernel.evaluate`` (one row per contact slot):

- ``corner`` slots 0-3: a load corner against the fence surface: E1's oblique strike (13),
  (23)-(33); the arc position starts from R = |O C_j| (23) and is refined by one projection onto
  the deflected fence, and D is the normal distance of C_j behind the fence surface at U (26).
- ``tip`` slots 4-7: the fence tip inside the load after a penetrating corner slid past it (the
  paper keeps E2's contact point C on the fence until it passes R_z, (21)); D is measured from
  the tip along the fence normal, continuous with the corner's D.
- ``border`` slots 8-11: a load corner against the fence-side border wall y0 = 0, D = -y_C2 (56),
  kinetic friction mu2 (E3, (50)-(55)).

Stages (``fence_sorter.codes.Stage``) are classified from the active set by
``kernel.classify_code``, not integrated as separate equations: a face along
the fence (E2) is a face whose two corners (or corner and the fence tip) both touch the fence, or
a single contact with the face within ``FLUSH_ANGLE`` of the fence tangent; that face's contact
pair holds it flush, the moment the paper's E2 (46) imposes by slaving phi to the fence.
"""

from __future__ import annotations

import math

FLUSH_ANGLE = math.radians(2.0)
