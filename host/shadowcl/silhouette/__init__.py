"""Silhouette (ridge) edges of a mesh against a light: the edge adjacency table, brute-force
classification on the device (kernels/silhouette.cl), and ordered loops.

One module serves the shadow-volume method (issue 6: extrude the oriented edges) and the angular
span table (issue 7: ridge-edge loops). Fawad, Wang & Wu, section III.B: an edge is a silhouette edge
when exactly one of its two faces faces the light.

Rules (the kernel, the reference and the tests share them):

- **Facing**: n = (v1 - v0) x (v2 - v0), s = n . (L - v0) for a point light, s = -n . d for a
  directional light travelling along d; light-facing means s > 0 strictly. A zero-area face and a face
  whose plane contains the light face no light.
- **Border edges** (one face) are silhouette edges when their face is light-facing: the missing face
  counts as not light-facing. The silhouettes are then the boundary of the light-facing region, so a
  shadow volume made of the light-facing faces, their silhouettes extruded and the same faces at
  infinity is closed for an open mesh too.
- **Degenerate faces**: a face with a repeated vertex index has no edges of its own (its "edges" are
  a point and a doubled segment, which would make a manifold edge look non-manifold); it is left out
  of the table and listed in :attr:`EdgeAdjacency.collapsed_faces`. A zero-area face with three
  distinct vertices (a sliver closing a T-junction) stays in the table and faces no light, so its
  edges next to light-facing faces are silhouettes of opposite sense that cancel in a volume.
- **Non-manifold edges** (three or more faces) are kept in the table, listed in
  :attr:`EdgeAdjacency.nonmanifold_edges`, given the code :data:`NONMANIFOLD` by the classifier (never
  dropped), and refused by :func:`silhouette_loops` and :meth:`EdgeAdjacency.require_manifold`.
- **Orientation**: a silhouette edge is oriented as its light-facing face runs along it, so with
  consistently wound faces the light-facing side is always on the same side of the oriented edge.
- **Ties**: the device decides in float32; faces whose plane passes within a rounding band of the
  light may differ from the float64 reference (see ``reference/silhouette.py``: ``tie_faces``).

Tables follow the mesh's vertex indices: vertices repeated at texture seams are not welded, so a
seam is a pair of border edges.

For a moving light, :class:`SilhouetteTracker` gives the same :class:`Silhouette` frame after frame
by brute force, by tracking (the paper's face walks, sections III.B-C) or by Markosian's randomized
method; bench/silhouettes.py measures their time and recall.

>>> adjacency = edge_adjacency(mesh)                     # cached per mesh
>>> sil = silhouette_edges(device, adjacency, light)     # codes, mask, oriented edges
>>> loops = silhouette_loops(sil)                        # closed vertex chains
>>> tracker = SilhouetteTracker(device, mesh, method="tracking")
>>> sil = tracker.update(light)                          # then the next light, and the next

Modules: :mod:`.classify` (facing and brute-force edge codes), :mod:`.loops` (closed oriented loops),
:mod:`.tracking` (:class:`SilhouetteTracker`); the edge adjacency is :mod:`shadowcl.topology`'s.

One name, three rooms: this package is the host room of ``kernels/silhouette.cl`` (a package, split by job,
where other names have one module); its NumPy reference is ``reference/silhouette.py``, its tests
``tests/test_silhouette.py``.
"""

from ..topology import EdgeAdjacency, edge_adjacency
from .classify import _facing_on_device  # noqa: F401 (bench/silhouettes.py launches it)
from .classify import NONMANIFOLD, Silhouette, face_facing, host_facing, silhouette_edges
from .loops import Loop, silhouette_loops, vertex_balance
from .tracking import TRACKER_METHODS, HalfEdges, SilhouetteTracker

__all__ = ["EdgeAdjacency", "HalfEdges", "Loop", "NONMANIFOLD", "Silhouette", "SilhouetteTracker", "TRACKER_METHODS",
           "edge_adjacency", "face_facing", "host_facing", "silhouette_edges", "silhouette_loops", "vertex_balance"]
