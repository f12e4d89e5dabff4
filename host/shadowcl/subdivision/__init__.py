"""Catmull-Clark subdivision surfaces: control meshes, exact limit evaluation, the patch table, tessellation.

A :class:`SubdivisionSurface` is a polygon control mesh (any polygons, boundaries allowed) whose limit
surface is evaluated exactly:

- Boundaries follow OpenSubdiv's "edge and corner" rule: boundary edges are B-spline curves of the
  boundary vertices, and a boundary vertex with a single face (valence 2) is a sharp corner.
- The surface is cut into quad patches that each carry at most one extraordinary vertex (EV): a control
  quad is a patch if every face at its corners is a quad and at most one corner is extraordinary; any
  other face is Catmull-Clark refined once (its children are the patches), and children with more than
  one EV once more. Refinement runs on the whole mesh in float64 NumPy (it is exact, and cheap).
- A regular patch is the 16-point uniform bicubic B-spline of its 4x4 control net; on a boundary the
  missing points are phantoms reflected through the boundary (P_-1 = 2 P_0 - P_1), which reproduces the
  boundary rules exactly. A patch with an EV is evaluated exactly by Stam's sub-domains: the local
  control net is subdivided L times in float64 (A^n C) and each level contributes three 16-point B-spline
  sub-patches; L is chosen so the level-L net lies within 2^-21 of its size from the EV's limit position
  (that position is used below 2^-L).

Parameters of a control face (``evaluate(face, u, v)``): a quad (v0, v1, v2, v3) in input order has
(0, 0) at v0, (1, 0) at v1, (1, 1) at v2 and (0, 1) at v3. An n-gon (n != 4) is split Ptex-style into n
sub-faces with ``u`` in [0, n]: sub-face j = floor(u) (u = n belongs to sub-face n - 1), local
(u - j, v) with (0, 0) at v_j, (1, 0) at the midpoint of edge (v_j, v_j+1), (1, 1) at the face centre and
(0, 1) at the midpoint of edge (v_j-1, v_j) (midpoints and centre on the limit surface, i.e. of the
once-refined mesh).

OpenSubdiv ``t`` tag lines in OBJ files (crease, corner, interpolateboundary, smoothtriangles, ...) are
ignored: every surface uses the rules above.

Modules, one job each: :mod:`.refinement` (polygon topology, one Catmull-Clark step, limit weights),
:mod:`.stam` (patch control nets, Stam's sub-domains), :mod:`.patches` (the patch table),
:mod:`.surface` (:class:`SubdivisionSurface`: checks, OBJ loading, evaluation, tessellation).

One name, three rooms: this package is the host room of ``kernels/subdivision.cl`` (a package, split by job,
where other names have one module); its NumPy reference is ``reference/subdivision.py``, its tests
``tests/test_subdivision.py``.
"""

from .patches import PatchTable
from .stam import MAX_STAM_LEVELS, STAM_TOLERANCE
from .surface import MAX_TESSELLATION_CELLS, NEAR_EV, TESSELLATION_TOLERANCE, SubdivisionSurface

__all__ = ["MAX_STAM_LEVELS", "MAX_TESSELLATION_CELLS", "NEAR_EV", "PatchTable", "STAM_TOLERANCE", "SubdivisionSurface", "TESSELLATION_TOLERANCE"]
