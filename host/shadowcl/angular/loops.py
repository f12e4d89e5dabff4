"""The ridge-edge loops (section 2) and the paper's loop-table input for the closed components (sections
4-5): lit regions, their loop edges, concave creases in duplicate and the pole's crossings; the table
module turns them into pairs on the device (:func:`~shadowcl.angular.table.loop_pairs`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import Mesh
from ..silhouette import silhouette_edges, silhouette_loops
from ..topology import components, concave_edges
from .frame import around_pole


def ridge_loops(device, mesh: Mesh, light):
    """The ridge-edge (RE) loops of ``mesh`` against ``light``: a list of :class:`~shadowcl.silhouette.Loop`.

    Section 2: every vertex meets an even number of ridge edges, so they chain into closed loops
    (several per object, nested or coiled). Checked here: the RE count at every vertex is even (the
    paper's property) and as many leave as arrive (the oriented form :func:`silhouette_loops` needs).
    Open meshes close their loops through their border edges; non-manifold or inconsistently wound
    meshes raise ``ValueError``.
    """
    sil = silhouette_edges(device, mesh, light)
    check_even_count(sil)
    try:
        return silhouette_loops(sil)
    except ValueError as error:
        raise ValueError(f"mesh: ridge-edge loops need a manifold, consistently wound mesh ({error})") from None


def ridge_degree(sil) -> np.ndarray:
    """(V,) number of ridge edges at each vertex."""
    nv = len(sil.adjacency.vertices)
    ends = sil.adjacency.edges[sil.indices].ravel()
    return np.bincount(ends, minlength=nv)


def check_even_count(sil) -> None:
    """Raise ``ValueError`` unless every vertex meets an even number of ridge edges (section 2's proof;
    :func:`silhouette_loops` then checks the oriented form, as many arriving as leaving)."""
    odd = np.flatnonzero(ridge_degree(sil) % 2)
    if len(odd):
        raise ValueError(f"mesh: {len(odd)} vertices meet an odd number of ridge edges, first {odd[:5].tolist()}; "
                         "the ridge-edge loops cannot close (non-manifold edges are left unclassified)")


@dataclass
class LoopSet:
    """The paper's table input for the closed components: ridge-edge ``loops``, the lit region of each loop
    edge in loop order (``regions``), and the concave ``creases`` ((K, 2) vertex ids) with theirs
    (``crease_regions``); ``poles``: signed X of each point where the pole axis pierces a lit face (point
    light), with its region (``pole_regions``)."""

    loops: list
    regions: np.ndarray
    creases: np.ndarray
    crease_regions: np.ndarray
    poles: np.ndarray
    pole_regions: np.ndarray


def lit_regions(adjacency, facing: np.ndarray) -> np.ndarray:
    """(F,) int: connected regions of light-facing faces (joined across edges with both faces facing the
    light), -1 for the others. The loops bounding one region (an outer loop and its holes) pair together."""
    pairs = adjacency.edge_faces[adjacency.face_count == 2]
    both = facing[pairs[:, 0]] & facing[pairs[:, 1]]
    return np.where(facing, components(len(facing), pairs[both]), -1)


def edge_regions(adjacency, facing: np.ndarray, edges: np.ndarray, regions: np.ndarray) -> np.ndarray:
    """(len(edges),) int32: the lit region (``regions``, per face) of each edge's (first) light-facing face."""
    two = adjacency.edge_faces[edges]
    lit = np.where(facing[two[:, 0]], two[:, 0], two[:, 1])
    return regions[lit].astype(np.int32)


def concave_creases(adjacency, facing: np.ndarray) -> np.ndarray:
    """Concave edges (:func:`shadowcl.topology.concave_edges`) between two light-facing faces: a valley
    seen from the light, which a chord between the loop's crossings would cut off. Section 5 inserts such
    edges in duplicate for depth; the convex ones lie in front of the chord and need none."""
    ids = np.flatnonzero(adjacency.face_count == 2)
    f = adjacency.edge_faces[ids]
    return concave_edges(adjacency, ids[facing[f[:, 0]] & facing[f[:, 1]]])


def pole_hits(adjacency, facing: np.ndarray, regions: np.ndarray, local) -> tuple[np.ndarray, np.ndarray]:
    """Where the pole axis (frame X, through a point light at the origin) pierces a light-facing face: (signed X
    of the hit, region). Every row's half-plane ends on that axis, so a lit region pierced there is cut in
    every row between a loop crossing and the pole: the pole enters the pairing as a crossing (s = +-1).
    None for a directional light (``local`` None: parallel rows)."""
    if local is None:
        return np.zeros(0), np.zeros(0, dtype=np.int32)
    lit = np.flatnonzero(facing)
    tri = np.asarray(local, dtype=np.float64)[adjacency.faces[lit]]
    around = around_pole(tri[:, :, 1], tri[:, :, 2])
    tri = tri[around]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ok = np.abs(n[:, 0]) > 0
    x = np.einsum("ij,ij->i", n[ok], tri[ok, 0]) / n[ok, 0]           # the plane met on the axis
    return x, regions[lit[around][ok]].astype(np.int32)
