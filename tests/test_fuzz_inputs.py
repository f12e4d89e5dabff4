"""Hostile files: mesh files (OBJ, OFF, PLY, STL) and scene files mutated by hypothesis.

Each example either loads a correct mesh or raises ValueError/TypeError (FileNotFoundError for a scene's
missing mesh) whose message names the file; nothing else may escape. Unmutated files must load the
mesh they were written from, and a mutation whose effect is known (a bad number, a bad index) must be
refused at its line. Examples are drawn from a fixed seed and counted (conftest.fuzz), so the run is bounded
(9 s here at load 10).
"""

import copy
import json
import math
import struct

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import shadowcl as sc
from conftest import fuzz

FUZZ = fuzz(100, deadline=5000)
FORMATS = ["obj", "off", "ply_ascii", "ply_le", "ply_be", "stl_ascii", "stl_binary"]
SUFFIX = {"obj": ".obj", "off": ".off", "stl_ascii": ".stl", "stl_binary": ".stl"}
BAD_NUMBERS = ["nan", "inf", "-inf", "1e39", "a", "1,5", "0x10", "--1", "\xff", "1e400"]


# ---- an independent writer for each format (polygons of 3 or 4 corners) ----


def write(fmt: str, vertices: np.ndarray, polygons: list) -> bytes:
    v, p = vertices.tolist(), polygons
    if fmt == "obj":
        return ("# fuzz\n" + "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in v)
                + "".join("f " + " ".join(str(i + 1) for i in f) + "\n" for f in p)).encode()
    if fmt == "off":
        return (f"OFF\n{len(v)} {len(p)} 0\n" + "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in v)
                + "".join(f"{len(f)} " + " ".join(map(str, f)) + "\n" for f in p)).encode()
    if fmt.startswith("ply"):
        kind = {"ply_ascii": "ascii", "ply_le": "binary_little_endian", "ply_be": "binary_big_endian"}[fmt]
        header = (f"ply\nformat {kind} 1.0\ncomment fuzz\nelement vertex {len(v)}\nproperty float x\n"
                  f"property float y\nproperty float z\nproperty uchar red\nelement face {len(p)}\n"
                  f"property list uchar int vertex_indices\nend_header\n").encode()
        if kind == "ascii":
            return header + ("".join(f"{x!r} {y!r} {z!r} 7\n" for x, y, z in v)
                             + "".join(f"{len(f)} " + " ".join(map(str, f)) + "\n" for f in p)).encode()
        order = "<" if fmt == "ply_le" else ">"
        body = b"".join(struct.pack(order + "fffB", *xyz, 7) for xyz in v)
        body += b"".join(struct.pack(order + "B" + "i" * len(f), len(f), *f) for f in p)
        return header + body
    triangles = [(f[0], f[j], f[j + 1]) for f in p for j in range(1, len(f) - 1)]
    if fmt == "stl_ascii":
        return ("solid fuzz\n" + "".join(
            "facet normal 0 0 0\nouter loop\n" + "".join(f"vertex {v[i][0]!r} {v[i][1]!r} {v[i][2]!r}\n" for i in t)
            + "endloop\nendfacet\n" for t in triangles) + "endsolid fuzz\n").encode()
    return (b"\0" * 80 + struct.pack("<I", len(triangles))
            + b"".join(struct.pack("<12fH", 0, 0, 0, *[c for i in t for c in v[i]], 0) for t in triangles))


def suffix(fmt: str) -> str:
    return SUFFIX.get(fmt, ".ply")


@st.composite
def meshes(draw):
    """(vertices float32-exact (V, 3), polygons of 3-4 distinct corners, every vertex used or not)."""
    count = draw(st.integers(3, 8))
    coordinate = st.floats(-1e6, 1e6, allow_nan=False, width=32)
    vertices = np.array(draw(st.lists(st.tuples(coordinate, coordinate, coordinate), min_size=count, max_size=count)),
                        dtype=np.float64)
    polygon = st.lists(st.integers(0, count - 1), min_size=3, max_size=4, unique=True)
    return vertices, draw(st.lists(polygon, min_size=1, max_size=6))


def fan(polygons: list) -> list:
    return [(f[0], f[j], f[j + 1]) for f in polygons for j in range(1, len(f) - 1)]


def assert_named(error: Exception, path) -> None:
    assert str(path) in str(error), f"the error does not name the file: {error}"


def load_or_named_error(path) -> "sc.Mesh | None":
    try:
        mesh = sc.Mesh.load(path)
    except (ValueError, TypeError) as error:
        assert_named(error, path)
        return None
    assert np.all(np.isfinite(mesh.vertices)) and mesh.faces.min() >= 0 and mesh.faces.max() < len(mesh.vertices)
    return mesh


def parsed(read, data: bytes):
    """A mesh reader's polygons as lists, or its error message: what two readers of one file must agree on."""
    try:
        polygons = read(data)
    except ValueError as error:
        return str(error)
    return polygons.vertices.tolist(), polygons.corners.tolist(), polygons.sizes.tolist()


@FUZZ
@given(mesh=meshes(), fmt=st.sampled_from(FORMATS))
def test_written_meshes_load_exactly(tmp_path, mesh, fmt):
    vertices, polygons = mesh
    path = tmp_path / f"m{suffix(fmt)}"
    path.write_bytes(write(fmt, vertices, polygons))
    loaded = sc.Mesh.load(path)
    expected = vertices[np.array(fan(polygons))]
    np.testing.assert_array_equal(loaded.triangles, expected)   # float32-exact coordinates: no rounding


@st.composite
def byte_mutations(draw, data: bytes):
    """``data`` truncated, cut, spliced with random bytes, or with a line duplicated."""
    kind = draw(st.sampled_from(["truncate", "delete", "insert", "overwrite", "duplicate_line"]))
    at = draw(st.integers(0, len(data)))
    if kind == "truncate":
        return data[:at]
    if kind == "delete":
        return data[:at] + data[at + draw(st.integers(1, 40)):]
    junk = draw(st.binary(min_size=1, max_size=12))
    if kind == "insert":
        return data[:at] + junk + data[at:]
    if kind == "overwrite":
        return data[:at] + junk + data[at + len(junk):]
    lines = data.split(b"\n")
    line = draw(st.integers(0, len(lines) - 1))
    return b"\n".join(lines[:line + 1] + lines[line:])


@FUZZ
@given(mesh=meshes(), fmt=st.sampled_from(FORMATS), data=st.data())
def test_mutated_bytes_load_or_name_the_file(tmp_path, mesh, fmt, data):
    path = tmp_path / f"m{suffix(fmt)}"
    path.write_bytes(data.draw(byte_mutations(write(fmt, *mesh))))
    load_or_named_error(path)


@FUZZ
@given(mesh=meshes(), fmt=st.sampled_from(["obj", "off", "ply_ascii", "stl_ascii"]), data=st.data())
def test_a_bad_number_is_refused_at_its_line(tmp_path, mesh, fmt, data):
    """A coordinate replaced by something that is not a finite float32 number: refused at that line."""
    vertices, polygons = mesh
    lines = write(fmt, vertices, polygons).decode().split("\n")
    vertex_lines = [i for i, line in enumerate(lines) if line.startswith(("v ", "vertex "))
                    or (fmt in ("off", "ply_ascii") and _is_vertex_row(fmt, lines, i, len(vertices)))]
    row = data.draw(st.sampled_from(vertex_lines))
    tokens = lines[row].split()
    column = data.draw(st.integers(len(tokens) - 3 - (fmt == "ply_ascii"), len(tokens) - 1 - (fmt == "ply_ascii")))
    tokens[column] = data.draw(st.sampled_from(BAD_NUMBERS))
    lines[row] = " ".join(tokens)
    path = tmp_path / f"m{suffix(fmt)}"
    path.write_bytes("\n".join(lines).encode("latin-1"))
    with pytest.raises(ValueError) as error:
        sc.Mesh.load(path)
    assert_named(error.value, path)
    assert f"line {row + 1}:" in str(error.value)


def _is_vertex_row(fmt: str, lines: list, index: int, count: int) -> bool:
    first = (2 if fmt == "off" else lines.index("end_header") + 1)
    return first <= index < first + count


@FUZZ
@given(mesh=meshes(), fmt=st.sampled_from(["obj", "off", "ply_ascii"]), data=st.data())
def test_a_bad_index_is_refused_at_its_line(tmp_path, mesh, fmt, data):
    """A face corner replaced by an index out of range (0 in OBJ, past the end, far past, negative
    beyond the start, not an integer): refused at that line."""
    vertices, polygons = mesh
    lines = write(fmt, vertices, polygons).decode().split("\n")
    header = {"obj": 1, "off": 2, "ply_ascii": lines.index("end_header") + 1 if fmt == "ply_ascii" else 0}[fmt]
    first = header + len(vertices)
    row = first + data.draw(st.integers(0, len(polygons) - 1))
    tokens = lines[row].split()
    column = data.draw(st.integers(1, len(tokens) - 1))
    base = 1 if fmt == "obj" else 0
    bad = data.draw(st.sampled_from([len(vertices) + base, 10**6, 2**40, -len(vertices) - 1, 10**30, "1.5", "x"]
                                    + ([0] if fmt == "obj" else [-1])))
    tokens[column] = str(bad)
    lines[row] = " ".join(tokens)
    path = tmp_path / f"m{suffix(fmt)}"
    path.write_text("\n".join(lines))
    with pytest.raises(ValueError) as error:
        sc.Mesh.load(path)
    assert_named(error.value, path)
    assert f"line {row + 1}:" in str(error.value)


@FUZZ
@given(mesh=meshes(), fmt=st.sampled_from(["off", "ply_ascii", "ply_le", "ply_be", "stl_binary"]),
       count=st.sampled_from([10**4, 2**31 - 1, 2**32 - 1, 10**12, 10**18]))
def test_huge_header_counts_are_refused_before_allocating(tmp_path, mesh, fmt, count):
    data = write(fmt, *mesh)
    if fmt == "stl_binary":
        data = data[:80] + struct.pack("<I", min(count, 2**32 - 1)) + data[84:]
    else:
        head, sep, body = data.partition(b"\nend_header\n" if fmt != "off" else b"\n")
        if fmt == "off":
            counts, sep2, rest = body.partition(b"\n")
            body = b"%d %d 0" % (count, count) + sep2 + rest
        else:
            head = head.replace(b"element face %d" % len(mesh[1]), b"element face %d" % count)
        data = head + sep + body
    path = tmp_path / f"m{suffix(fmt)}"
    path.write_bytes(data)
    with pytest.raises(ValueError) as error:
        sc.Mesh.load(path)
    assert_named(error.value, path)


def with_count(fmt: str, data: bytes, element: str, old: int, new: int) -> bytes:
    """``data`` with the header count of ``element`` ("vertex" or "face") changed from ``old`` to ``new``."""
    if fmt == "off":
        lines = data.split(b"\n")
        nv, nf, ne = lines[1].split()
        lines[1] = b" ".join([b"%d" % new, nf, ne] if element == "vertex" else [nv, b"%d" % new, ne])
        return b"\n".join(lines)
    if fmt == "stl_binary":
        return data[:80] + struct.pack("<I", new) + data[84:]
    head, sep, body = data.partition(b"end_header\n")
    return head.replace(b"element %s %d\n" % (element.encode(), old), b"element %s %d\n" % (element.encode(), new)) + sep + body


@FUZZ
@given(mesh=meshes(), fmt=st.sampled_from(["off", "ply_ascii", "stl_binary", "ply_le", "ply_be"]),
       element=st.sampled_from(["vertex", "face"]), change=st.sampled_from([-3, -2, -1, 1, 2, 3]))
def test_wrong_header_counts_are_refused(tmp_path, mesh, fmt, element, change):
    """A count a little off (too small would silently drop the rest): refused, naming the file; binary PLY
    rows have no separators, so there the shifted bytes may happen to parse and only a named error or a
    valid mesh is required."""
    vertices, polygons = mesh
    old = len(fan(polygons)) if fmt == "stl_binary" else len(vertices) if element == "vertex" else len(polygons)
    path = tmp_path / f"m{suffix(fmt)}"
    path.write_bytes(with_count(fmt, write(fmt, vertices, polygons), element, old, max(old + change, 0)))
    if fmt.startswith("ply_") and fmt != "ply_ascii":
        load_or_named_error(path)
        return
    with pytest.raises(ValueError) as error:
        sc.Mesh.load(path)
    assert_named(error.value, path)


# ---- scene files: a valid scene, then at most one mutation at a random key path ----

HOSTILE_VALUES = st.sampled_from([0, -1, 2, 0.5, 1e-300, 1e39, 1e300, math.nan, math.inf, -math.inf, 2**31,
                                  2**63 - 1, -2**63, 10**9, 2049, 524290, 1.5, "x", "", True, [], [1, 2],
                                  [0, 0, 0], [1e39, 0, 0], [[1]], {"a": 1}])
VECTOR = st.sampled_from([[0, 1, 0], [5, -2, 1], [0.3, 0.2, -0.1]])
TRANSFORM = st.fixed_dictionaries({}, optional={"scale": st.sampled_from([2, 0.5, [1, 2, 1], -1]),
                                                "rotate": st.sampled_from([[0, 90, 0], [10, 20, 30]]),
                                                "translate": VECTOR})
PRIMITIVE = st.one_of(
    st.builds(dict, sphere=st.fixed_dictionaries({}, optional={"radius": st.sampled_from([0.5, 1, 2]),
                                                                "segments": st.sampled_from([4, 8, 12])})),
    st.builds(dict, box=st.fixed_dictionaries({}, optional={"size": st.sampled_from([1, [1, 2, 0.5]]),
                                                             "center": st.booleans()})),
    st.builds(dict, cylinder=st.fixed_dictionaries({}, optional={"height": st.sampled_from([1, 2]),
                                                                  "radius_top": st.sampled_from([0, 0.5]),
                                                                  "segments": st.sampled_from([3, 8])})),
    st.just({"triangles": {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "faces": [[0, 1, 2]]}}),
)
SOLID = PRIMITIVE.filter(lambda shape: "triangles" not in shape)
CSG = st.recursive(SOLID, lambda children: st.builds(
    lambda op, items, transform: {op: items, **transform}, st.sampled_from(["union", "difference"]),
    st.lists(children, min_size=1, max_size=2), TRANSFORM), max_leaves=4)
SHAPE = st.builds(lambda shape, transform: {**shape, **transform}, st.one_of(PRIMITIVE, CSG), TRANSFORM)
LIGHT = st.one_of(st.builds(dict, type=st.just("point"), position=st.just([0, 8, 0])),
                  st.builds(dict, type=st.just("directional"), direction=st.just([0.2, -1, 0.1])))
SCENE = st.fixed_dictionaries({"lights": st.lists(LIGHT, min_size=1, max_size=2),
                               "objects": st.lists(SHAPE, min_size=1, max_size=3)},
                              optional={"name": st.just("fuzz"), "render": st.just({"width": 64, "height": 48}),
                                        "camera": st.just({"position": [6, 4, 8], "target": [0, 0, 0]})})


def key_paths(value, path=()):
    """Every path to a value inside nested dicts and lists."""
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for key, item in items:
        yield path + (key,)
        yield from key_paths(item, path + (key,))


@st.composite
def mutated_scenes(draw):
    """(scene dict, whether it was mutated): one value replaced, one key removed or one unknown key added."""
    scene = copy.deepcopy(draw(SCENE))   # st.just values are shared between examples
    kind = draw(st.sampled_from(["none", "replace", "replace", "delete", "add"]))
    if kind == "none":
        return scene, False
    path = draw(st.sampled_from(list(key_paths(scene))))
    parent = scene
    for key in path[:-1]:
        parent = parent[key]
    if kind == "replace":
        parent[path[-1]] = draw(HOSTILE_VALUES)
    elif kind == "delete":
        del parent[path[-1]]
    else:
        target = parent if isinstance(parent, dict) else parent[path[-1]]
        if isinstance(target, dict):
            target["bogus"] = 1
    return scene, True


def toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value == math.inf else "-inf" if value == -math.inf
                                                 else repr(value))
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(item) for item in value) + "]"
    return "{ " + ", ".join(f"{json.dumps(key)} = {toml_value(item)}" for key, item in value.items()) + " }"


@FUZZ
@given(case=mutated_scenes())
def test_mutated_scene_files_load_or_name_the_file(tmp_path, case):
    scene, mutated = case
    path = tmp_path / "fuzz.toml"
    path.write_text("".join(f"{json.dumps(key)} = {toml_value(value)}\n" for key, value in scene.items()))
    try:
        loaded = sc.Scene.load(path)
    except (ValueError, TypeError, FileNotFoundError) as error:
        assert str(error).startswith(f"{path}: "), error
        assert mutated or "is empty" in str(error), error   # a difference may remove everything
        return
    assert np.all(np.isfinite(loaded.mesh.vertices)) and np.all(np.isfinite(loaded.bounds))
    if not mutated:
        assert len(loaded.objects) == len(scene["objects"]) and len(loaded.lights) == len(scene["lights"])


@pytest.mark.parametrize("depth, inline", [(64, False), (65, False), (300, False), (64, True), (65, True),
                                           (1000, True)])
def test_nesting_is_bounded_with_the_key_path(tmp_path, depth, inline):
    light = '[[lights]]\ntype = "point"\nposition = [0, 5, 0]\n'
    if inline:
        shape = "{ sphere = { segments = 4 } }"
        for _ in range(depth - 1):
            shape = f"{{ union = [{shape}] }}"
        text = light + f"[[objects]]\nunion = [{shape}]\n"
    else:
        keys = ["objects"] + ["union"] * depth
        text = light + "".join(f"[[{'.'.join(keys[:i + 1])}]]\n" for i in range(depth + 1)) + "sphere = { segments = 4 }\n"
    path = tmp_path / "nested.toml"
    path.write_text(text)
    if depth <= 64:
        assert len(sc.Scene.load(path).mesh.faces) > 0
        return
    with pytest.raises(ValueError) as error:
        sc.Scene.load(path)
    message = str(error.value)
    assert message.startswith(f"{path}: ")
    assert ("objects[0]" in message and "CSG nested more than 64 deep" in message) or "too deep for the TOML parser" in message


# ---- the bulk OBJ path against the line parser: the same polygons or the same error on every file ----

OBJ_HOSTILE = ["0", "1e", "1.2.3", "nan", "inf", "-", "+", "/2", "99999999999999999999", "9223372036854775807",
               "1_0", "0x1p3", "1\r", "\xa0", "é", "1e39", "12345678901234567890123", "-9"]


def obj_records(hostile: bool):
    """Records of plain tokens (which the bulk path reads), or of plain tokens now and then a hostile one."""
    def records(keywords, good):
        tokens = st.sampled_from(good * 10 + OBJ_HOSTILE if hostile else good)
        return st.tuples(st.sampled_from(keywords), st.lists(tokens, min_size=3, max_size=5),
                         st.sampled_from([" ", "\t", "  "]))

    others = ["vt", "vn", "#", "o", ""] + ([" v", "\tf", "v\r", "f\r"] if hostile else [])
    return st.lists(st.one_of(records(["v"], ["1", "-1", "2", "+2", "3", "1.5", "-.5e3"]),
                              records(["f"], ["1", "2", "3", "-1", "-2", "-3", "+2", "1/2/3", "1//2", "-2/1", "2/x"]),
                              records(others, ["1", "a"])), max_size=12)


@fuzz(300, deadline=5000)
@given(records=st.one_of(obj_records(False), obj_records(True)), newline=st.sampled_from(["\n", "\r\n"]))
def test_bulk_obj_agrees_with_the_line_parser(records, newline):
    """Files of valid and hostile OBJ records: the bulk reader (which hands what it declines to the line
    parser) gives the line parser's polygons or its exact error message."""
    from shadowcl import meshio

    data = newline.join(keyword + separator + separator.join(tokens)
                        for keyword, tokens, separator in records).encode("latin-1")

    assert parsed(meshio._read_obj, data) == parsed(meshio._read_obj_by_line, data)


def test_bulk_obj_reads_the_common_forms():
    """The bulk path itself (not the line parser) reads slashes, negative indices, extra vertex values,
    tabs, CRLF, comments and blank lines, so the agreement test above compares two parsers."""
    from shadowcl import meshio

    data = (b"# comment \xe9\r\nmtllib a.mtl\r\nv 0 0 0 1\r\nv\t1 0 0 0.5 0.5 0.5\r\nv 0 1 0\r\n\r\n   \r\n"
            b"vt 0 0\r\nvn 0 0 1\r\nf 1/1/1 2//1 3\r\nv 1 1 0\r\nf -1 -2 -3 1/1\r\ns off\r\n")
    polygons = meshio._read_obj_bulk(data)
    assert polygons is not None
    assert polygons.vertices.tolist() == [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]
    assert polygons.corners.tolist() == [0, 1, 2, 3, 2, 1, 0] and polygons.sizes.tolist() == [3, 4]


OFF_GOOD_VERTEX = ["0", "1", "-1.5", "2e-1", "+3"]


@fuzz(300, deadline=5000)
@given(counts=st.tuples(st.integers(0, 4), st.integers(0, 4)), data=st.data(),
       extra=st.sampled_from(["", "0", "x"]), hostile=st.booleans(), newline=st.sampled_from(["\n", "\r\n"]))
def test_bulk_off_agrees_with_the_line_parser(counts, data, extra, hostile, newline):
    """OFF files of plain and hostile rows (counts off by one, sizes past the row, floats as indices,
    colours after a face, blank lines, comments): the bulk reader gives the line parser's outcome."""
    from shadowcl import meshio

    nv, nf = counts
    bad = OFF_HOSTILE if hostile else []
    rows = [" ".join(data.draw(st.lists(st.sampled_from(OFF_GOOD_VERTEX * 10 + bad), min_size=3 - hostile, max_size=5)))
            for _ in range(nv + data.draw(st.sampled_from([-1, 0, 0, 0, 1])) * hostile)]
    for _ in range(nf):
        size = data.draw(st.sampled_from([3, 3, 4] + ([0, 5, "+3", "3.0"] if hostile else [])))
        length = data.draw(st.integers(3, 4)) if hostile else size   # hostile: maybe not the row's size
        good = [str(i) for i in range(nv)] if nv and not hostile else ["0", "1", "2", "3"]
        corners = data.draw(st.lists(st.sampled_from(good * 10 + bad), min_size=length, max_size=length))
        rows.append(" ".join([str(size)] + corners + data.draw(st.sampled_from([[], ["0.5", "1", "0"]]))))
    if hostile and rows:
        rows.insert(data.draw(st.integers(0, len(rows))), data.draw(st.sampled_from(["", "  ", "", "# note"])))
    text = newline.join(["OFF", f"{nv} {nf} {extra}".strip()] + rows) + newline

    def outcome(read):
        try:
            polygons = read(text.encode("latin-1"))
        except ValueError as error:
            return str(error)
        return polygons.vertices.tolist(), polygons.corners.tolist(), polygons.sizes.tolist()

    assert outcome(meshio._read_off) == outcome(meshio._read_off_by_line)
    if not hostile:   # the bulk path itself reads plain files
        try:
            assert meshio._read_off_bulk(text.encode("latin-1")) is not None
        except ValueError:
            pass   # the bulk path itself found the problem (an index past the vertices)


OFF_HOSTILE = ["1e", "nan", "-", "1.0", "-1", "99999999999999999999", "a", "1_0", "\xa0"]


STL_HOSTILE_LINES = ["VERTEX 1 2 3", "vertex 1 2", "vertex 1 2 3 4", "vertex 1 nan 2", "vertex 1 1e 2", "vertexx 1 2 3",
                     "endfacet", "bogus", "vertex 1\xa02 3", "vertex 0x1 2 3"]


@fuzz(200, deadline=5000)
@given(facets=st.lists(st.lists(st.tuples(st.sampled_from(["0", "1", "-2.5", "3e-2", "+4"]), st.sampled_from(["", "  ", "\t"])),
                                min_size=3, max_size=3), max_size=4),
       hostile=st.lists(st.tuples(st.integers(1, 40), st.sampled_from(STL_HOSTILE_LINES)), max_size=2),
       newline=st.sampled_from(["\n", "\r\n"]))
def test_bulk_ascii_stl_agrees_with_the_line_parser(facets, hostile, newline):
    """ASCII STL files of plain facets (indented or not) with now and then a hostile line: the bulk reader
    gives the line parser's outcome, and reads the plain ones itself."""
    from shadowcl import meshio

    lines = ["solid fuzz"]
    for corners in facets:
        lines += ["facet normal 0 0 1", " outer loop"]
        lines += [f"{indent}vertex {x} {x} 1" for x, indent in corners]
        lines += [" endloop", "endfacet"]
    lines.append("endsolid fuzz")
    for at, line in hostile:
        lines.insert(min(at, len(lines)), line)
    data = newline.join(lines).encode("latin-1")

    assert parsed(meshio._read_stl, data) == parsed(meshio._read_ascii_stl_by_line, data)
    if not hostile and facets:
        assert meshio._read_ascii_stl_bulk(data) is not None


PLY_HOSTILE = ["1.0", "-1", "1e", "nan", "a", "+2", "99999999999999999999", "\xa0"]


@fuzz(200, deadline=5000)
@given(nv=st.integers(0, 4), nf=st.integers(0, 3), flag=st.booleans(), hostile=st.booleans(), data=st.data())
def test_bulk_ascii_ply_agrees_with_the_line_parser(nv, nf, flag, hostile, data):
    """ASCII PLY files (x y z, maybe an int property; faces of a list) of plain and hostile rows (short
    rows, lists longer than their row, floats as indices, row counts off by one): the bulk reader gives
    the line parser's outcome, and reads the plain ones itself."""
    from unittest import mock

    from shadowcl import meshio

    bad = PLY_HOSTILE if hostile else []
    number, integer = st.sampled_from(["0", "1", "-2.5", "3e-1"] * 40 + bad), st.sampled_from(["0", "-3", "7"] * 40 + bad)
    vertex = st.tuples(number, number, number, integer if flag else st.just(""), st.sampled_from(["", "", "5"]))
    rows = [" ".join(data.draw(vertex)).strip() for _ in range(nv + hostile * data.draw(st.sampled_from([0, 0, -1, 1])))]
    for _ in range(nf):
        corners = data.draw(st.lists(st.sampled_from([str(i) for i in range(max(nv, 1))] * 40 + bad), min_size=3, max_size=4))
        size = str(len(corners) + hostile * data.draw(st.sampled_from([0, 0, 1, -1])))
        rows.append(" ".join([data.draw(st.sampled_from([size] * 10 + bad))] + corners))
    header = ["ply", "format ascii 1.0", f"element vertex {nv}", "property float x", "property float y",
              "property float z"] + (["property int flag"] if flag else []) + [
              f"element face {nf}", "property list uchar int vertex_indices", "end_header"]
    data_bytes = "\n".join(header + rows + [""]).encode("latin-1")

    def outcome():
        try:
            polygons = meshio._read_ply(data_bytes)
        except ValueError as error:
            return str(error)
        return polygons.vertices.tolist(), polygons.corners.tolist(), polygons.sizes.tolist()

    real, bulk_results = meshio._ply_ascii_bulk, []
    with mock.patch.object(meshio, "_ply_ascii_bulk", lambda *args: bulk_results.append(real(*args)) or bulk_results[-1]):
        with_bulk = outcome()
    with mock.patch.object(meshio, "_ply_ascii_bulk", lambda *args: None):
        assert with_bulk == outcome()
    assert hostile or bulk_results[0] is not None   # the bulk path itself reads plain files
