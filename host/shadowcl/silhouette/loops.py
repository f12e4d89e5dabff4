"""Silhouette edges chained into closed, oriented loops (the ridge-edge loops of the angular method)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from .classify import Silhouette


@dataclass(frozen=True)
class Loop:
    """One closed chain of oriented silhouette edges: ``vertices[i] -> vertices[i + 1]`` (wrapping
    around) is the edge ``edges[i]`` of the adjacency table."""

    vertices: np.ndarray
    edges: np.ndarray


def silhouette_loops(silhouette: Silhouette) -> list[Loop]:
    """The silhouette edges chained into closed loops, each edge followed by one leaving its head.

    Every vertex has as many silhouette edges arriving as leaving when the winding is consistent and
    every edge has one or two faces (the silhouettes bound the light-facing region), so the loops
    close; a vertex where several loops touch pairs its arriving and leaving edges in edge order.
    Raises ``ValueError`` for non-manifold or inconsistently wound meshes, and if a vertex is
    unbalanced.
    """
    silhouette.adjacency.require_manifold("silhouette_loops: mesh")
    index = silhouette.indices
    tails, heads = silhouette.oriented.T
    unbalanced = np.flatnonzero(vertex_balance(silhouette))
    if len(unbalanced):
        raise ValueError(f"silhouette_loops: {len(unbalanced)} vertices with unequal arriving and leaving "
                         f"silhouette edges, first {unbalanced[:5].tolist()}; the loops cannot close")
    # Sorted by vertex, the k-th edge arriving at v is followed by the k-th edge leaving v.
    leaving = np.argsort(tails, kind="stable")
    arriving = np.argsort(heads, kind="stable")
    successor = np.empty(len(index), dtype=np.int64)
    successor[arriving] = leaving
    return [Loop(vertices=tails[chain], edges=index[chain]) for chain in _cycles(successor)]


def vertex_balance(silhouette: Silhouette) -> np.ndarray:
    """(V,) silhouette edges leaving minus arriving at each vertex: zero everywhere when loops close."""
    tails, heads = silhouette.oriented.T
    nvertices = len(silhouette.adjacency.vertices)
    return np.bincount(tails, minlength=nvertices) - np.bincount(heads, minlength=nvertices)


def _cycles(successor: np.ndarray) -> list[np.ndarray]:
    """The cycles of the permutation ``successor``, each from its lowest member, lowest first.

    Vectorised by pointer doubling (log2 of the length rounds) rather than a Python walk per edge:
    first each member learns its cycle's lowest member, then its distance to the member before it.
    """
    n = len(successor)
    rounds = max(int(np.ceil(np.log2(max(n, 1)))), 1)
    lowest, jump = np.arange(n), successor
    for _ in range(rounds):                       # after k rounds: the minimum over 2**k steps ahead
        lowest, jump = np.minimum(lowest, lowest[jump]), jump[jump]
    last = successor == lowest                    # the member whose successor starts the cycle
    jump = np.where(last, np.arange(n), successor)
    to_last = (~last).astype(np.int64)
    for _ in range(rounds):                       # list ranking: steps to the cycle's last member
        to_last, jump = to_last + to_last[jump], jump[jump]
    order = np.lexsort((-to_last, lowest))
    return np.split(order, np.flatnonzero(np.diff(lowest[order])) + 1) if n else []
