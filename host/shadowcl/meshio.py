"""Mesh files: OBJ, OFF, PLY (ASCII and binary) and STL (ASCII and binary) read into polygons.

Read here rather than through a dependency so that every malformed file raises a ValueError naming
the file (and the line, for text), never an IndexError from inside a parser or a silently wrong mesh.
Text is decoded as Latin-1 (ASCII numbers, comments in any encoding); counts in headers are checked
against what the file holds before anything is allocated; vertices must be finite and within float32;
every polygon needs at least three corners, each a valid vertex index.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .checks import VertexIndexError, vertex_indices

MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off")
FLOAT32_MAX = float(np.finfo(np.float32).max)


@dataclass(frozen=True)
class Polygons:
    """Polygons as read: ``vertices`` (V, 3) float64, ``corners`` (K,) int64 vertex indices of every
    polygon in turn, ``sizes`` (P,) int64 corners per polygon (each >= 3, summing to K)."""

    vertices: np.ndarray
    corners: np.ndarray
    sizes: np.ndarray

    def triangles(self) -> np.ndarray:
        """(T, 3) int64: each polygon fan-triangulated from its first corner."""
        if np.all(self.sizes == 3):   # triangles already (most files): no fan to build
            return self.corners.reshape(-1, 3)
        starts = np.cumsum(self.sizes) - self.sizes
        fans = self.sizes - 2
        first = np.repeat(starts, fans)
        step = np.arange(fans.sum()) - np.repeat(np.cumsum(fans) - fans, fans)  # 0 .. fans - 1 per polygon
        return np.stack([self.corners[first], self.corners[first + step + 1], self.corners[first + step + 2]], axis=1)

    def polygon_list(self) -> list[np.ndarray]:
        return np.split(self.corners, np.cumsum(self.sizes)[:-1])


class _Malformed(ValueError):
    """A problem at ``line`` (None: no line, a binary file); :func:`read_polygons` adds the file."""

    def __init__(self, message: str, line: int | None = None):
        super().__init__(message if line is None else f"line {line}: {message}")


def path_argument(name: str, value) -> Path:
    """``value`` as a Path; anything but a string or path-like is a TypeError naming ``name``."""
    if not isinstance(value, (str, os.PathLike)):
        raise TypeError(f"{name}: expected a file path, got {type(value).__name__}")
    return Path(value)


def read_polygons(path, suffixes=MESH_SUFFIXES, what: str = "mesh file") -> Polygons:
    """The polygons of the mesh file at ``path`` (format by suffix, one of ``suffixes``; ``what`` names
    the file in a not-found error)."""
    path = path_argument("path", path)
    suffix = path.suffix.lower()
    if suffix not in suffixes:
        raise ValueError(f"path: {path}: unsupported mesh format {suffix!r}; expected one of {suffixes}")
    if not path.is_file():
        raise FileNotFoundError(f"path: no {what} at {path}")
    try:
        data = path.read_bytes()
    except OSError as error:
        raise ValueError(f"{path}: cannot be read ({error.strerror})") from None
    try:
        return _READERS[suffix](data)
    except _Malformed as error:
        raise ValueError(f"path: {path}: {error}") from None


def _lines(data: bytes) -> list[str]:
    return data.decode("latin-1").split("\n")


def _numbers(tokens: list[str], kind, line: int, what: str) -> list:
    """``tokens`` as ``kind`` (float or int; integers must fit in 64 bits)."""
    try:
        values = [kind(token) for token in tokens]
    except ValueError:
        raise _Malformed(f"expected {what}, got {' '.join(tokens)!r}", line) from None
    if kind is int and any(abs(value) >= 2**63 for value in values):
        raise _Malformed(f"an integer does not fit in 64 bits: {' '.join(tokens)!r}", line)
    return values


def _checked(vertices: np.ndarray, corners: np.ndarray, sizes: np.ndarray, vertex_lines=None,
             polygon_lines=None, index_base: int = 0) -> Polygons:
    """The polygons after the checks every format shares; lines (when known) locate the first problem,
    and a bad index is reported as the file wrote it (counted from ``index_base``)."""
    def where(lines, index):
        return None if lines is None else lines[index]

    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    corners = np.asarray(corners, dtype=np.int64)
    sizes = np.asarray(sizes, dtype=np.int64)
    if len(sizes) == 0:
        raise _Malformed("no faces")
    bad = np.flatnonzero(~np.all(np.isfinite(vertices) & (np.abs(vertices) < FLOAT32_MAX), axis=1))
    if len(bad):
        raise _Malformed(f"vertex {bad[0]} is NaN, infinite or beyond float32: {vertices[bad[0]].tolist()}",
                         where(vertex_lines, bad[0]))
    small = np.flatnonzero(sizes < 3)
    if len(small):
        raise _Malformed(f"face {small[0]} has {sizes[small[0]]} corners; a face needs at least 3",
                         where(polygon_lines, small[0]))
    try:
        vertex_indices("faces", corners, len(vertices), sizes, index_base)
    except VertexIndexError as error:
        raise _Malformed(str(error), where(polygon_lines, error.face)) from None
    return Polygons(vertices, corners, sizes)


# ---- OBJ: "v x y z" and "f i j k ..." records, 1-based (negative: counted back from the last vertex) ----


def _read_obj(data: bytes) -> Polygons:
    bulk = _read_obj_bulk(data)
    return bulk if bulk is not None else _read_obj_by_line(data)


def _byte_set(chars: bytes) -> np.ndarray:
    table = np.zeros(256, dtype=bool)
    table[list(chars)] = True
    return table


# the other bytes str.split() takes for whitespace in Latin-1: a file holding one goes to the line parser
UNUSUAL_SPACE = b"\x0b\x0c\x1c\x1d\x1e\x1f\x85\xa0"
FLOAT_BYTES = _byte_set(b"0123456789.+-eE \t\r\n")   # no letters: NumPy and float() differ on 'nan', hex
INDEX_BYTES = _byte_set(b"0123456789+- \t\r\n")
FLOAT_MARKS = _byte_set(b".eE")   # what a float has and an int() does not


def _is_space(text: np.ndarray) -> np.ndarray:
    """Space, tab, CR or LF, per byte (comparisons: faster than a table lookup on megabytes)."""
    return (text == 32) | (text == 10) | (text == 9) | (text == 13)


def _has_unusual_space(data: bytes) -> bool:
    return any(byte in data for byte in UNUSUAL_SPACE)


def _bulk_numbers(text: np.ndarray, dtype, count: int) -> np.ndarray | None:
    """The ``count`` whitespace-separated numbers of ``text`` (uint8), or None unless NumPy reads exactly
    ``count`` numbers to the end."""
    if count == 0:
        return np.zeros(0, dtype=dtype)   # NumPy reads a blank text as [-1]
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)   # NumPy's word for "stopped at a bad token"
        try:
            values = np.fromstring(text.tobytes(), dtype=dtype, sep=" ")
        except (ValueError, DeprecationWarning):
            return None
    return values if len(values) == count else None


def _tokens(text: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start of every whitespace-separated token of ``text`` (uint8, lines ending in newline) as a
    boolean per byte, and the line (counted within ``text``) of each token."""
    space = _is_space(text)
    start = ~space & np.concatenate([[True], space[:-1]])
    return start, np.searchsorted(np.flatnonzero(text == 10), np.flatnonzero(start))


def _non_blank_lines(token_line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The lines holding tokens (given each token's line, in order) and the index of each one's first token."""
    new_line = np.ones(len(token_line), dtype=bool)
    new_line[1:] = token_line[1:] != token_line[:-1]
    return token_line[new_line], np.flatnonzero(new_line)


def _integer_tokens(text: np.ndarray, start: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Per token of ``text`` (``start``: its tokens' first bytes; ``values``: their numbers): written as
    an integer int() reads (no '.', 'e') and exact in float64."""
    if not len(values):
        return np.zeros(0, dtype=bool)
    token_starts = np.flatnonzero(start)   # a token's bytes run to the next token's start (spaces between)
    return ~np.logical_or.reduceat(FLOAT_MARKS[text], token_starts) & (np.abs(values) < 2**53)


def _list_items(first: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """Token indices of rows' lists: ``sizes[i]`` tokens after the token ``first[i]`` (their length)."""
    return np.repeat(first + 1, sizes) + (np.arange(sizes.sum()) - np.repeat(np.cumsum(sizes) - sizes, sizes))


def _read_obj_bulk(data: bytes) -> Polygons | None:
    """The polygons of an OBJ file whose 'v' and 'f' records are plain numbers, parsed in bulk; None
    when a record needs the line parser (which then reads the unusual form or names the problem), so
    both give the same result on every file."""
    text = np.frombuffer(data + b"\n", dtype=np.uint8)
    if _has_unusual_space(data):
        return None
    ends = np.flatnonzero(text == 10)
    starts = np.concatenate([[0], ends[:-1] + 1])
    first, second = text[starts], text[np.minimum(starts + 1, len(text) - 1)]
    keyed = (ends - starts >= 2) & _is_space(second)
    is_vertex, is_face = keyed & (first == ord("v")), keyed & (first == ord("f"))
    if np.any((ends - starts == 1) & np.isin(first, (ord("v"), ord("f")))):
        return None   # a bare keyword
    blank_start = np.flatnonzero(_is_space(first) & (ends > starts))
    if any(data[starts[line]:ends[line]].strip() for line in blank_start):
        return None   # a record after whitespace
    kind = np.zeros(len(starts), dtype=np.int8)
    kind[is_vertex], kind[is_face] = 1, 2
    line_kind = np.repeat(kind, ends - starts + 1)
    work = text.copy()
    work[starts[keyed]] = ord(" ")   # the keyword

    vertex_text = work[line_kind == 1]
    if not FLOAT_BYTES[vertex_text].all():
        return None
    _, token_line = _tokens(vertex_text)
    counts = np.bincount(token_line, minlength=np.count_nonzero(is_vertex))
    values = _bulk_numbers(vertex_text, np.float64, len(token_line))
    if values is None or (len(counts) and counts.min() < 3):
        return None
    first_three = (np.cumsum(counts) - counts)[:, None] + np.arange(3)   # extra numbers (w, colour) dropped
    vertices = values[first_three]

    face_text = work[line_kind == 2]
    start, token_line = _tokens(face_text)
    slash = face_text == ord("/")
    if slash.any():   # "v/vt/vn": keep v, blank the rest of the token
        slashes = np.cumsum(slash, dtype=np.int32)
        slashes_before = np.concatenate([[0], (slashes - slash)[start]])   # per token; 0 before the first
        after_slash = slashes - slashes_before[np.cumsum(start, dtype=np.int32)] > 0
        face_text[after_slash & ~_is_space(face_text)] = ord(" ")
    if not INDEX_BYTES[face_text].all():
        return None
    indices = _bulk_numbers(face_text, np.int64, len(token_line))
    limits = np.iinfo(np.int64)
    if indices is None or np.isin(indices, (limits.min, limits.max)).any():
        return None   # a missing vertex index, or one NumPy clipped to 64 bits
    sizes = np.bincount(token_line, minlength=np.count_nonzero(is_face))
    vertices_before = np.repeat(np.cumsum(is_vertex)[is_face], sizes)
    if np.any((indices == 0) | (-indices > vertices_before)):
        return None
    corners = np.where(indices > 0, indices - 1, vertices_before + indices)
    return _checked(vertices, corners, sizes, np.flatnonzero(is_vertex) + 1, np.flatnonzero(is_face) + 1,
                    index_base=1)


def _read_obj_by_line(data: bytes) -> Polygons:
    vertices, vertex_lines, corners, sizes, polygon_lines = [], [], [], [], []
    for number, line in enumerate(_lines(data), 1):
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            if len(parts) < 4:
                raise _Malformed(f"a vertex needs three coordinates: {line.strip()!r}", number)
            vertices.append(_numbers(parts[1:4], float, number, "three numbers after 'v'"))
            vertex_lines.append(number)
        elif parts[0] == "f":
            # "f v", "f v/vt", "f v//vn", "f v/vt/vn": the vertex index comes first
            indices = _numbers([token.split("/")[0] for token in parts[1:]], int, number,
                               f"vertex indices after 'f' in {line.strip()!r}")
            for index in indices:
                if index == 0 or -index > len(vertices):
                    raise _Malformed(f"vertex index {index} is not valid here (OBJ counts from 1; negative "
                                     f"indices count back from the {len(vertices)} vertices so far)", number)
            corners.extend(i - 1 if i > 0 else len(vertices) + i for i in indices)
            sizes.append(len(indices))
            polygon_lines.append(number)
    # positive indices may refer to vertices listed later: _checked tests them once all are read
    return _checked(vertices, corners, sizes, vertex_lines, polygon_lines, index_base=1)


# ---- OFF: "OFF", then "V F E", V vertex lines and F lines "n i1 .. in" (0-based); '#' comments ----


def _read_off(data: bytes) -> Polygons:
    bulk = _read_off_bulk(data)
    return bulk if bulk is not None else _read_off_by_line(data)


def _read_off_bulk(data: bytes) -> Polygons | None:
    """The polygons of an OFF file without comments, its header and counts on lines of their own, parsed
    in bulk; None when the line parser must read it or name its problem (both agree on every file)."""
    if b"#" in data:
        return None
    text = np.frombuffer(data + b"\n", dtype=np.uint8)
    if _has_unusual_space(data):
        return None
    start, token_line = _tokens(text)
    lines, first = _non_blank_lines(token_line)
    if len(lines) < 2 or first[1] != 1:     # the header alone on its line, then the counts
        return None
    ends = np.flatnonzero(text == 10)
    keyword, *counts = data[:ends[lines[1]]].decode("latin-1").split()
    if not (keyword.isalpha() and keyword.endswith("OFF")) or len(counts) < 2 or not all(c.isdigit() for c in counts[:2]):
        return None
    nv, nf = int(counts[0]), int(counts[1])
    if nv + nf != len(lines) - 2:
        return None
    body = text[ends[lines[1]] + 1:]
    if not FLOAT_BYTES[body].all():
        return None
    start, first = start[ends[lines[1]] + 1:], first[2:] - (1 + len(counts))   # body tokens from 0
    values = _bulk_numbers(body, np.float64, np.count_nonzero(start))
    if values is None:
        return None
    sizes_per_line = np.diff(np.append(first, len(values)))          # tokens on each line
    vertex_first, face_first = first[:nv], first[nv:]
    if nv and sizes_per_line[:nv].min() < 3:
        return None
    vertices = values[vertex_first[:, None] + np.arange(3)]
    integer = _integer_tokens(body, start, values)
    sizes = values[face_first]
    signed = np.isin(body[np.flatnonzero(start)[face_first]], np.frombuffer(b"+-", dtype=np.uint8))
    if not (integer[face_first].all() and not signed.any() and np.all(sizes < 2**31)   # as str.isdigit()
            and np.all(sizes_per_line[nv:] >= sizes + 1)):
        return None
    sizes = sizes.astype(np.int64)
    used = _list_items(face_first, sizes)
    if not integer[used].all():
        return None
    return _checked(vertices, values[used].astype(np.int64), sizes, lines[2:2 + nv] + 1, lines[2 + nv:] + 1)


def _read_off_by_line(data: bytes) -> Polygons:
    records = []  # (line number, tokens) of the non-empty lines, comments removed
    for number, line in enumerate(_lines(data), 1):
        tokens = line.split("#", 1)[0].split()
        if tokens:
            records.append((number, tokens))
    if not records or not (records[0][1][0].isalpha() and records[0][1][0].endswith("OFF")):
        raise _Malformed("expected the header 'OFF' on the first line", records[0][0] if records else 1)
    header_line, header = records[0]
    rest = records[1:]
    counts = header[1:] if len(header) > 1 else (rest.pop(0)[1] if rest else [])
    if len(counts) < 2:
        raise _Malformed("expected the counts 'vertices faces [edges]'", header_line + (len(header) == 1))
    nv, nf = _numbers(counts[:2], int, header_line, "integer counts")
    if nv < 0 or nf < 0 or nv + nf > len(rest):
        raise _Malformed(f"the header announces {nv} vertices and {nf} faces but the file has "
                         f"{len(rest)} more lines", header_line)
    vertices, vertex_lines = [], []
    for number, tokens in rest[:nv]:
        if len(tokens) < 3:
            raise _Malformed(f"a vertex needs three coordinates, got {' '.join(tokens)!r}", number)
        vertices.append(_numbers(tokens[:3], float, number, "three coordinates"))
        vertex_lines.append(number)
    corners, sizes, polygon_lines = [], [], []
    for number, tokens in rest[nv:nv + nf]:
        size = int(tokens[0]) if tokens[0].isdigit() else -1
        if size < 0 or len(tokens) < size + 1:
            raise _Malformed(f"expected a face 'n i1 .. in', got {' '.join(tokens)!r}", number)
        corners.extend(_numbers(tokens[1:size + 1], int, number, "integer vertex indices"))  # a colour may follow
        sizes.append(size)
        polygon_lines.append(number)
    if len(rest) > nv + nf:   # a count too small would otherwise drop the rest silently
        raise _Malformed(f"more lines than the header's {nv} vertices and {nf} faces", rest[nv + nf][0])
    return _checked(vertices, corners, sizes, vertex_lines, polygon_lines)


# ---- STL: binary (80-byte header, count, 50 bytes a triangle) or ASCII facets; three vertices each ----


def _read_stl(data: bytes) -> Polygons:
    if len(data) >= 84:
        count = int.from_bytes(data[80:84], "little")
        if len(data) == 84 + 50 * count:
            rows = np.frombuffer(data, dtype=np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)),
                                                       ("attribute", "<u2")]), count=count, offset=84)
            return _triangle_soup(rows["corners"].reshape(-1, 3))
    if not data.lstrip()[:5].lower() == b"solid":
        raise _Malformed(f"neither a binary STL (its {len(data)} bytes do not match the triangle count in "
                         f"the header) nor an ASCII one (which starts with 'solid')")
    bulk = _read_ascii_stl_bulk(data)
    return bulk if bulk is not None else _read_ascii_stl_by_line(data)


STL_KEYWORDS = (b"vertex", b"endfacet", b"solid", b"endsolid", b"facet", b"outer", b"endloop")


def _read_ascii_stl_bulk(data: bytes) -> Polygons | None:
    """The triangles of an ASCII STL whose keywords are lower case and whose facets hold three vertices
    of three numbers each, parsed in bulk; None when the line parser must read it or name its problem."""
    text = np.frombuffer(data + b"\n", dtype=np.uint8)
    if _has_unusual_space(data):
        return None
    start, token_line = _tokens(text)
    lines, first = _non_blank_lines(token_line)
    tokens_per_line = np.diff(np.append(first, len(token_line)))
    at = np.flatnonzero(start)[first]                                # where each line's first word begins
    width = max(map(len, STL_KEYWORDS)) + 1
    words = text[np.minimum(at[:, None] + np.arange(width), len(text) - 1)]
    kind = np.full(len(lines), -1)
    for index, keyword in enumerate(STL_KEYWORDS):
        pattern = np.frombuffer(keyword, dtype=np.uint8)
        kind[np.all(words[:, :len(pattern)] == pattern, axis=1) & _is_space(words[:, len(pattern)])] = index
    vertex, end_facet = kind == 0, kind == 1
    facets = kind[vertex | end_facet]   # must run vertex, vertex, vertex, endfacet, ...
    if (kind < 0).any() or np.any(tokens_per_line[vertex] != 4) or len(facets) % 4 or not np.all(
            facets.reshape(-1, 4) == [0, 0, 0, 1]):
        return None
    work = text.copy()
    work[at[vertex][:, None] + np.arange(len(STL_KEYWORDS[0]))] = ord(" ")   # the keyword
    ends = np.flatnonzero(text == 10)
    line_starts = np.concatenate([[0], ends[:-1] + 1])
    is_vertex_line = np.zeros(len(ends), dtype=np.int8)
    is_vertex_line[lines[vertex]] = 1
    vertex_text = work[np.repeat(is_vertex_line, ends - line_starts + 1) == 1]
    if not FLOAT_BYTES[vertex_text].all():
        return None
    values = _bulk_numbers(vertex_text, np.float64, 3 * np.count_nonzero(vertex))
    if values is None:
        return None
    return _triangle_soup(values.reshape(-1, 3), lines[vertex] + 1)


def _read_ascii_stl_by_line(data: bytes) -> Polygons:
    vertices, vertex_lines, in_facet = [], [], 0
    for number, line in enumerate(_lines(data), 1):
        parts = line.split()
        if not parts:
            continue
        keyword = parts[0].lower()
        if keyword == "vertex":
            if len(parts) != 4:
                raise _Malformed(f"expected 'vertex x y z', got {line.strip()!r}", number)
            vertices.append(_numbers(parts[1:], float, number, "three coordinates"))
            vertex_lines.append(number)
            in_facet += 1
        elif keyword == "endfacet":
            if in_facet != 3:
                raise _Malformed(f"a facet needs exactly 3 vertices, this one has {in_facet}", number)
            in_facet = 0
        elif keyword not in ("solid", "endsolid", "facet", "outer", "endloop"):
            raise _Malformed(f"unexpected {parts[0]!r} in an ASCII STL", number)
    if in_facet or len(vertices) % 3:
        raise _Malformed("the last facet is not closed by 'endfacet'")
    return _triangle_soup(vertices, vertex_lines)


def _triangle_soup(vertices, vertex_lines=None) -> Polygons:
    count = len(vertices) // 3
    return _checked(vertices, np.arange(3 * count), np.full(count, 3), vertex_lines)


# ---- PLY: a header of elements and properties, then ASCII rows or packed binary rows ----

PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
             "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
             "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
PLY_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
FACE_LISTS = ("vertex_indices", "vertex_index")


@dataclass
class _Element:
    name: str
    count: int
    line: int
    properties: list  # (name, type, None) or (name, item type, count type) for lists


def _read_ply(data: bytes) -> Polygons:
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise _Malformed("not a PLY file (expected 'ply' first and an 'end_header' line)")
    body_start = data.find(b"\n", end) + 1 or len(data)
    header = data[:end].decode("latin-1").split("\n")
    order, elements = None, []
    for number, line in enumerate(header, 1):
        parts = line.split()
        if not parts or parts[0] in ("ply", "comment", "obj_info"):
            continue
        if parts[0] == "format" and len(parts) == 3 and parts[1] in PLY_FORMATS:
            order = PLY_FORMATS[parts[1]] or "ascii"
        elif parts[0] == "element" and len(parts) == 3:
            count = _numbers(parts[2:], int, number, "an element count")[0]
            if count < 0:
                raise _Malformed(f"negative element count {count}", number)
            elements.append(_Element(parts[1], count, number, []))
        elif parts[0] == "property" and elements and len(parts) == 3 and parts[1] in PLY_TYPES:
            elements[-1].properties.append((parts[2], PLY_TYPES[parts[1]], None))
        elif (parts[0] == "property" and elements and len(parts) == 5 and parts[1] == "list"
              and parts[2] in PLY_TYPES and parts[3] in PLY_TYPES and PLY_TYPES[parts[2]][0] in "iu"):
            elements[-1].properties.append((parts[4], PLY_TYPES[parts[3]], PLY_TYPES[parts[2]]))
        else:
            raise _Malformed(f"not a PLY header line: {line.strip()!r}", number)
        if elements and len({name for name, _, _ in elements[-1].properties}) < len(elements[-1].properties):
            raise _Malformed(f"property {parts[-1]!r} appears twice", number)
    if order is None:
        raise _Malformed("the header has no valid 'format' line")
    by_name = {element.name: element for element in elements}
    vertex, face = by_name.get("vertex"), by_name.get("face")
    if vertex is None or face is None:
        raise _Malformed("expected a 'vertex' and a 'face' element")
    names = [name for name, _, length in vertex.properties if length is None]
    if not all(axis in names for axis in "xyz"):
        raise _Malformed(f"the vertex element needs number properties x, y and z, has {names}", vertex.line)
    lists = [name for name, kind, length in face.properties
             if length is not None and name in FACE_LISTS and not kind.startswith("f")]
    if not lists:
        raise _Malformed(f"the face element needs an integer list property {' or '.join(FACE_LISTS)}", face.line)
    if order == "ascii":
        bulk = _ply_ascii_bulk(data, body_start, elements, len(header))
        rows, row_lines = bulk if bulk is not None else _ply_ascii(data, body_start, elements, len(header))
    else:
        rows, row_lines = _ply_binary(data, body_start, elements, order), {}
    xyz = np.stack([rows["vertex"][axis] for axis in "xyz"], axis=1)
    polygons = rows["face"][lists[0]]
    if isinstance(polygons, np.ndarray) and polygons.ndim == 2:   # every face has the same number of corners
        sizes, corners = np.full(len(polygons), polygons.shape[1]), polygons.ravel()
    else:   # a list of faces, or no face at all (an empty 1-D array)
        sizes = np.array([len(p) for p in polygons], dtype=np.int64)
        corners = np.concatenate(polygons) if len(polygons) else np.zeros(0, np.int64)
    return _checked(xyz, corners.astype(np.int64), sizes, row_lines.get("vertex"), row_lines.get("face"))


def _ply_ascii_bulk(data: bytes, start: int, elements: list, header_lines: int) -> tuple[dict, dict] | None:
    """:func:`_ply_ascii`'s result parsed in bulk, for elements of numbers only or of one list only (a
    face); None when the line parser must read the rows or name their problem (both agree on every file)."""
    if _has_unusual_space(data):
        return None
    body = np.frombuffer(data[start:] + b"\n", dtype=np.uint8)
    if not FLOAT_BYTES[body].all():
        return None
    start_byte, token_line = _tokens(body)
    lines, first = _non_blank_lines(token_line)
    if len(lines) != sum(element.count for element in elements):
        return None
    values = _bulk_numbers(body, np.float64, len(token_line))
    if values is None:
        return None
    tokens_per_line = np.diff(np.append(first, len(values)))
    integer = _integer_tokens(body, start_byte, values)

    def numbers(used, kind):   # the values at token indices ``used``, or None where int() would refuse one
        return values[used] if kind.startswith("f") or integer[used].all() else None

    rows, row_lines, at = {}, {}, 0
    for element in elements:
        row_first, row_tokens = first[at:at + element.count], tokens_per_line[at:at + element.count]
        row_lines[element.name] = lines[at:at + element.count] + header_lines + 1
        at += element.count
        if all(length is None for _, _, length in element.properties):
            if len(row_first) and row_tokens.min() < len(element.properties):
                return None
            rows[element.name] = {}
            for column, (name, kind, _) in enumerate(element.properties):
                rows[element.name][name] = numbers(row_first + column, kind)
                if rows[element.name][name] is None:
                    return None
        elif len(element.properties) == 1:
            (name, kind, _), = element.properties
            sizes = numbers(row_first, "int")
            if sizes is None or np.any(sizes < 0) or np.any(row_tokens < sizes + 1):
                return None
            sizes = sizes.astype(np.int64)
            items = numbers(_list_items(row_first, sizes), kind)
            if items is None:
                return None
            items = items if kind.startswith("f") else items.astype(np.int64)
            uniform = len(sizes) and np.all(sizes == sizes[0])
            rows[element.name] = {name: items.reshape(len(sizes), sizes[0]) if uniform else
                                  np.split(items, np.cumsum(sizes)[:-1]) if len(sizes) else []}
        else:
            return None
    return rows, row_lines


def _ply_ascii(data: bytes, start: int, elements: list, header_lines: int) -> tuple[dict, dict]:
    """({element: {property: values}}, {element: line number of each row})."""
    lines = [(number, line.split()) for number, line in enumerate(_lines(data[start:]), header_lines + 1)]
    lines = [(number, tokens) for number, tokens in lines if tokens]
    needed = sum(element.count for element in elements)
    if needed != len(lines):   # a count too small would otherwise drop the rest silently
        raise _Malformed(f"the header announces {needed} rows but the file has {len(lines)} more lines",
                         lines[needed][0] if needed < len(lines) else None)
    rows, row_lines, at = {}, {}, 0
    for element in elements:
        values = {name: [] for name, _, _ in element.properties}
        row_lines[element.name] = [number for number, _ in lines[at:at + element.count]]
        for number, tokens in lines[at:at + element.count]:
            position = 0
            for name, kind, length in element.properties:
                parse = float if kind.startswith("f") else int
                if length is None:
                    items = tokens[position:position + 1]
                    position += 1
                else:
                    size = _numbers(tokens[position:position + 1], int, number, f"the length of list {name!r}")
                    if not size or size[0] < 0:
                        raise _Malformed(f"row of {element.name!r} ends before list {name!r}", number)
                    items = tokens[position + 1:position + 1 + size[0]]
                    position += 1 + size[0]
                if position > len(tokens):
                    raise _Malformed(f"row of {element.name!r} ends before property {name!r}", number)
                parsed = _numbers(items, parse, number, f"numbers for {name!r}")
                values[name].append(parsed[0] if length is None else np.array(parsed))
        at += element.count
        rows[element.name] = {name: (np.array(v, dtype=np.float64) if not v or np.isscalar(v[0]) else v)
                              for name, v in values.items()}
    return rows, row_lines


def _ply_binary(data: bytes, start: int, elements: list, order: str) -> dict:
    """{element: {property: values}} of rows packed in byte ``order``."""
    rows, at = {}, start
    for element in elements:
        scalars = [(name, order + kind) for name, kind, length in element.properties if length is None]
        minimum = element.count * (sum(np.dtype(kind).itemsize for _, kind in scalars)
                                   + sum(np.dtype(length).itemsize for _, _, length in element.properties if length))
        if at + minimum > len(data):
            raise _Malformed(f"element {element.name!r}: the header announces {element.count} rows, "
                             f"at least {minimum} bytes, but {len(data) - at} remain", element.line)
        if all(length is None for _, _, length in element.properties):
            table = np.frombuffer(data, dtype=np.dtype(scalars), count=element.count, offset=at)
            rows[element.name] = {name: table[name].astype(np.float64) for name, _ in scalars}
            at += table.nbytes
        else:
            rows[element.name], at = _ply_binary_rows(data, at, element, order)
    if data[at:].strip():
        raise _Malformed(f"{len(data) - at} bytes follow the last row the header announces")
    return rows


def _ply_binary_rows(data: bytes, at: int, element: _Element, order: str) -> tuple[dict, int]:
    """Rows holding lists: one packed table when every list has the first row's length, else row by row."""
    def fixed_dtype(lengths):
        fields = []
        for (name, kind, length), size in zip(element.properties, lengths):
            fields += [(name, order + kind)] if length is None else [(f"{name}#", order + length), (name, order + kind, (size,))]
        return np.dtype(fields)

    lengths, offset = [], at
    for name, kind, length in element.properties:   # the first row gives the lengths to try
        if length is None:
            lengths.append(0)
            offset += np.dtype(kind).itemsize
        else:
            size = int(np.frombuffer(data, order + length, 1, offset)[0]) if offset + np.dtype(length).itemsize <= len(data) else -1
            lengths.append(size)
            offset += np.dtype(length).itemsize + max(size, 0) * np.dtype(kind).itemsize
    if element.count and min(lengths) >= 0 and at + element.count * (offset - at) <= len(data):
        dtype = fixed_dtype(lengths)
        if at + element.count * dtype.itemsize <= len(data):
            table = np.frombuffer(data, dtype=dtype, count=element.count, offset=at)
            uniform = all(np.all(table[f"{name}#"] == size)
                          for (name, _, length), size in zip(element.properties, lengths) if length is not None)
            if uniform:
                return {name: table[name].astype(np.float64 if length is None else table[name].dtype)
                        for name, _, length in element.properties}, at + table.nbytes
    values = {name: [] for name, _, _ in element.properties}
    for row in range(element.count):
        for name, kind, length in element.properties:
            size = 1
            if length is not None:
                if at + np.dtype(length).itemsize > len(data):
                    raise _Malformed(f"element {element.name!r} row {row}: the file ends inside it")
                size = int(np.frombuffer(data, order + length, 1, at)[0])
                at += np.dtype(length).itemsize
            nbytes = size * np.dtype(kind).itemsize
            if size < 0:
                raise _Malformed(f"element {element.name!r} row {row}: list {name!r} has negative length {size}")
            if at + nbytes > len(data):
                raise _Malformed(f"element {element.name!r} row {row}: the file ends inside it")
            items = np.frombuffer(data, order + kind, size, at)
            values[name].append(float(items[0]) if length is None else items)
            at += nbytes
    return {name: (np.array(v) if length is None else v) for (name, _, length), v in zip(element.properties, values.values())}, at


_READERS = {".obj": _read_obj, ".off": _read_off, ".stl": _read_stl, ".ply": _read_ply}
