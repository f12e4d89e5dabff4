"""The angular method: discretized shadow volumes in angular coordinates (Thakur, Cheng & Miura).

Pipeline (kernels/angular.cl):

1. **Ridge-edge loops** (section 2): :func:`ridge_loops` chains the ridge edges of
   :mod:`shadowcl.silhouette` (edges with exactly one light-facing face) into closed loops and checks
   the paper's even-count property at every vertex. Open meshes close their loops through their border
   edges (the silhouette module counts the missing face as hidden); non-manifold meshes are refused.
2. **Frame** (:func:`angular_frame`): the light at the origin; a row is a half-plane through the X axis
   at ``theta = atan2(Y, -Z)`` (the paper's eq. 2 extended to the whole circle, so a light inside the
   scene needs no hemisphere split: rows wrap round at +-pi); inside a row a direction is keyed by
   ``s = X / r = sin(psi)``, monotone in the paper's ``phi = atan(X / -Z)``. The poles are +-X: the frame
   keeps them away from the occluder directions (for ``render``, on the camera's right axis when that
   clears them by :data:`POLE_CLEARANCE`, so that a scan line stays in one row). A directional light
   uses parallel rows (planes Y = const, s = X).
3. **Table** (sections 3-5, 7.1), built on the device: per table face, its plane and the rows whose
   band ``[t0 + k dt, t0 + (k + 1) dt]`` its row-coordinate range meets, widened by :data:`ANGLE_PAD`
   (first row, count); the records per row and their exclusive prefix sum on the host (a
   difference array over the faces' row intervals: per-row atomic counters on the device contended on a
   few hundred addresses, 0.45 s for 600 k faces); a fill pass writing one record per (face, row, piece) at its
   row's offset plus an atomic cursor, then a sort of each row by ``s_lo`` (kernels/lists.h)
   (the paper's pairwise sort). A record is the face's span ``[s_lo, s_hi]`` over the row's whole band
   (the face clipped to the band's wedge -- slab for a directional light --, s extreme at a corner or where
   an edge's great circle comes nearest the pole; widened by :data:`S_PAD`; a wide one cut into pieces of
   at most 1 / :data:`PIECES` of the s range, as a span across the row -- a ground under the occluders --
   kept the lookups' backward scan from stopping early: 100 000 cubes on a ground, 600 rows, 500 000
   receivers: 2.70 -> 0.59 s, the loop table 0.27 s) -- the paper's pair of
   crossings: a ridge-edge crossing where the face touches a loop, a visible-edge crossing otherwise, so
   visible edges enter "in duplicate" (section 5) -- plus the face plane for depth. Pairs therefore come
   from one face each: loops never need the local-peak pairing of section 4 to pair correctly, however
   they coil (the reference builds the paper's loop-only table with that pairing and the tests check both
   agree). A lookup tests the face itself: the plane (exact depth instead of r interpolated between the
   pair's ends), then the triangle's three edge functions (watertight: a shared edge's function is
   computed from its lower vertex index, the same bits for both faces). Since every direction the face
   covers in the band lies in its span, no face is missed, and since the hit must lie in the triangle, no
   plane counts past its face's edges: the table has no discretization error (see below).
   Table faces: the light-facing faces of each closed manifold component (a blocked ray always crosses
   one); every face of an open or non-manifold component (a ray can be stopped by a hidden face there).
3b. **The paper's table** (``table="loops"``, :func:`loop_pairs`): for the closed components, each ridge
   edge's crossings with the rows it spans are counted, prefix-summed and filled on the device like the
   face records (``edge_rows``, ``fill_edges``: s, the crossing point -- its r --, the way the loop goes in
   theta); one work-item per row (``pair_rows``) sorts its crossings and pairs them by section 4's rule
   (in s order a crossing going the way the group's first one goes waits, one going the other way closes
   the oldest waiting: the chains leaving a local theta peak bound one span, so coils pair correctly).
   The sort and pairing (``stats["pair_s"]``) took 6 ms / 49 ms for 57 k / 288 k crossings (10 000 /
   100 000 cubes, 600 rows, 4 % of the prepare): on the device it pays, as the FIFO is a sequential scan
   per row that NumPy cannot vectorise (a host version would be a Python loop over the crossings after
   a read-back; not written, so that side is an estimate). What costs is host-side: chaining the loops
   (silhouette_loops) and labelling regions and creases. Groups are *lit regions* (faces facing
   the light joined across edges whose faces both face it) rather than single loops: a region's outer loop
   and its holes' loops pair together, so a torus lit from above keeps its hole lit (loop by loop, the
   outer loop's pair spans the hole and shadowed it: 1006 of 2276 ground points under it). Depth
   (section 5): a pair's record holds the plane of its chord, the segment between its two crossing points,
   i.e. r interpolated between the pair's ends; off the row's centre plane the chord plane follows the mean
   of the two edges' directions (along the row plane's normal, receivers on the occluder's own lit cap fell
   behind it: half of a slab's top). A chord cuts off a valley of the lit cap, so the region's concave
   creases (edges between two lit faces folding inwards) enter "in duplicate" and cut the pairs they fall
   in (A h1, h1 h2, ..., hn B) -- the paper's "visible edges in duplicate", only where the depth needs
   them (convex creases lie in front of the chord). Hidden edges in duplicate (the paper's main form) were
   not used: the far surface's chords would need the hidden faces' own chaining, which is what a face
   record already is. A point light's rows end on the pole axis; a lit face it pierces adds a crossing
   at s = +-1 in every row (without it the pillars round the pole in the light-inside scene lost their
   shadows: 225 wrong pixels against 12). Open and non-manifold components keep face records in the same
   rows (their hidden faces can stop rays, and their loops need not close).
   Default ``table="faces"``: exact but for float32 ties, where the loop table keeps its half-row band
   (bench/results/angular_revisions.md: 0 of 500 000 receivers wrong on bunny, ogre and teapot at the
   default rows, 0.094 / 0.105 / 0.037 % before; angular_caps.md: no false shadow or light on any
   occluder or ground set). The row-centre spans it replaced (a face listed in the rows whose centre it
   spans, cut there, its plane tested without its edges: the paper's discretization) falsely shadowed
   15-22 % of the receivers lying on a sphere's, torus's or cylinder's lit cap under a directional light (a
   receiver up to half a row off the centre met a neighbouring face's plane extended past its edge);
   testing the triangle against those spans removed the caps' errors but missed the faces a row's centre
   does not cut (46-101 false lights per 1,500 ground receivers). Band spans list each face in about one
   more row than row-centre spans did (which left most small faces in no row at all), and wide ones in
   pieces: at the default rows 193 k -> 311 k records on the bunny, 133 k -> 263 k on the ogre, 65 k ->
   108 k on the teapot; the lookups test more candidates, and a plane hit also its edges (9-32 % of the
   lookup time, against a plane-only build): ``Shadows.mask`` took 1.23 / 1.37 / 1.13 x its old time on
   500 000 receivers, ``sc.prepare`` 1.35 / 1.35 / 1.39 x (medians of the interleaved rounds' ratios,
   load ~8.5 on 2 shared cores). The loop table keeps the paper's error and is slower to build (its loops are
   chained on the host).
4. **Lookups**: per receiver, its row and ``s``; a binary search finds the records starting at or
   before ``s``, a backward scan tests them (first hit wins) and stops where the row's running maximum
   of ``s_hi`` falls below ``s`` (section 7 step 2, without walking the whole entry). ``classify_view``
   walks each scan line (in pieces of :data:`RUN_PIECE` pixels, for parallelism) keeping the state and
   the interval of ``s`` it holds over (the paper's ``nextX``), so one lookup serves a run of pixels. The
   run is re-validated per pixel by its row and ``s`` (known from the Z-buffer's receivers) instead of
   eq. 7's maximum run length; that makes it exact: runs give the per-pixel answer bit for bit. For the
   rows to follow the scan lines, ``classify_view`` puts the pole on the camera's right axis (the
   paper's frame, XY parallel to the screen) and picks the rows from the image (:meth:`view_rows`).
5. **Several lights** (section 11.1): one table per light, ``sc.shadow_counts(..., method="angular")``. **Light inside the
   scene** (section 11.2): the rows are half-planes round the pole axis, so the whole sphere but the
   pole is covered by one table whose rows wrap round at +-pi; no hemisphere split is needed, and rows
   are uniform in theta (the paper's finer rows near +-pi/2 compensate its tan-based coordinates, which
   these rows do not use).

A point light inside a closed solid (winding number of a closed component round it >= 1/2) raises
``ValueError``: every point outside that solid is in its shadow, and no face of it turns to the light.

Error: with ``table="faces"`` a receiver differs from the exact method only by float32 rounding (a ray
within ~1e-6 of a face's size from its edge, or a hit within rounding of eps): rows and spans are widened
past the receivers' float32 row coordinate and s (:data:`ANGLE_PAD`, :data:`S_PAD`, :data:`LENGTH_PAD`),
so a receiver on a row boundary meets the same faces in either row. With ``table="loops"`` the pairs are
cut at the row's centre: a receiver can differ when its ray passes within half a row (in theta; in Y for
a directional light) of a loop edge, near shadow boundaries and terminators.

>>> method = AngularMethod(get_device(), theta_resolution=600)
>>> method.prepare(mesh, light, receiver_bounds, eps)
>>> mask = method.classify(points, normals)

Modules, one job each: :mod:`.frame` (the angular frame, its row coordinate and rows), :mod:`.loops` (the
ridge-edge loops and the paper's loop-table input: lit regions, concave creases, pole hits), :mod:`.table`
(the lookup table built on the device: face records, loop pairs, row counts) and :mod:`.method`
(:class:`AngularMethod`, the light-inside check).

One name, three rooms: this package is the host room of ``kernels/angular.cl`` (a package, split by job,
where other names have one module); its NumPy reference is ``reference/angular.py``, its tests
``tests/test_angular.py``.
"""

from .frame import (ANGLE_PAD, DEFAULT_ROWS, LENGTH_PAD, MAX_ROWS, MIN_ROWS, PIECES, POLE_CLEARANCE, S_PAD, Frame,
                    angular_frame, row_coordinate, rows_from_receivers)
from .loops import (LoopSet, check_even_count, concave_creases, edge_regions, lit_regions, pole_hits, ridge_degree,
                    ridge_loops)
from .method import (FULL_CIRCLE_SPAN, ROWS_PER_LINE, RUN_PIECE, SAMPLE, TABLES, AngularMethod, light_inside)
from .table import (REC_FLOATS, Table, build_table, check_capacity, frame_options, loop_pairs, row_counts,
                    table_entries)

__all__ = ["ANGLE_PAD", "AngularMethod", "DEFAULT_ROWS", "FULL_CIRCLE_SPAN", "Frame", "LENGTH_PAD", "LoopSet",
           "MAX_ROWS", "MIN_ROWS", "PIECES", "POLE_CLEARANCE", "REC_FLOATS", "ROWS_PER_LINE", "RUN_PIECE", "SAMPLE",
           "S_PAD", "TABLES", "Table", "angular_frame", "build_table", "check_capacity", "check_even_count",
           "concave_creases", "edge_regions", "frame_options", "light_inside", "lit_regions", "loop_pairs",
           "pole_hits", "ridge_degree", "ridge_loops", "row_coordinate", "row_counts", "rows_from_receivers",
           "table_entries"]
