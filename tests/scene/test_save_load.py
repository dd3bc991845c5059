"""Scene.save / Scene.load and pickling: the same answers without a build, one copy of each
array in a pickle, and a ValueError (never a crash) for files that are truncated, corrupt,
crafted or newer."""

import json
import pickle
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from raycore import Scene, arrayfile, scene_file
from raycore.bvh.leaves import FACE_COLUMN, face_ints

from .brute import random_scene, scene_rays, shared_mesh


def every_kind(dtype):
    """The 37-object scene of every kind (meshes, prototypes, instances, each analytic shape)
    and, beside it, a shared mesh file's mesh placed twice (one placement of an instance)."""
    spec, _ = random_scene(3)
    scene = spec.scene(dtype, max_leaf_size=6, bins=12)
    bunny = shared_mesh("stanford-bunny")
    g = scene.add_mesh(bunny.vertices * 20, bunny.faces)
    moved = np.eye(4)
    moved[:3, 3] = [0, 20, 0]
    scene.add_instance(scene.add_instance(g, moved), moved)
    return scene


def answers(scene, rays):
    origins, directions, tmin, tmax, _ = rays
    hits = scene.intersect(origins, directions, tmin, tmax, fields=("uv", "normal", "point"))
    every = scene.intersect_all(origins, directions, tmin, tmax)
    return {"t": hits.t, "geom_id": hits.geom_id, "prim_id": hits.prim_id, "uv": hits.uv,
            "normal": hits.normal, "point": hits.point,
            "occluded": scene.occluded(origins, directions, tmin, tmax),
            "count": scene.count(origins, directions, tmin, tmax),
            "all_t": every.t, "all_geom": every.geom_id, "all_prim": every.prim_id,
            "contains": scene.contains(origins), "bounds": np.stack(scene.bounds)}


@pytest.fixture(scope="module", params=("float32", "float64"))
def saved(request, tmp_path_factory):
    """A scene of every kind, its answers, and the file it was saved to."""
    scene = every_kind(request.param)
    rays = scene_rays(3)
    path = tmp_path_factory.mktemp("scenes") / "scene.rcs"
    scene.save(path)
    return scene, answers(scene, rays), path, rays


@pytest.mark.parametrize("how", ["read", "mmap", "pickle"])
def test_round_trip_answers_equal(saved, how):
    scene, expected, path, rays = saved
    if how == "pickle":
        loaded = pickle.loads(pickle.dumps(scene))
    else:
        loaded = Scene.load(path, mmap=how == "mmap")
    assert loaded.dtype == scene.dtype and loaded.build_params == scene.build_params
    assert len(loaded) == len(scene) and loaded.triangle_count == scene.triangle_count
    got = answers(loaded, rays)
    for name, value in expected.items():
        np.testing.assert_array_equal(got[name], value, err_msg=name)
    # the rays reach every object, so that every kind's stored data was used
    assert set(expected["all_geom"]) == set(range(len(scene))) - {
        i for i in range(len(scene)) if not scene._visible[i]}
    assert loaded.stats() == scene.stats()


def test_loaded_scene_skips_the_build_and_can_grow(saved):
    scene, _, path, rays = saved
    loaded = Scene.load(path)
    assert loaded._record is not None  # ready for queries without build()
    # adding objects rebuilds the top tree over the stored meshes' trees, as in the original
    grown = pickle.loads(pickle.dumps(scene))
    for target in (loaded, grown):
        target.add_sphere([0.5, 0.25, 0.125], 2.0)
        target.add_instance(len(scene) - 1, np.diag([1.5, 1.5, 1.5, 1.0]))
    assert loaded._record is None
    got, want = answers(loaded, rays), answers(grown, rays)
    for name, value in want.items():
        np.testing.assert_array_equal(got[name], value, err_msg=name)
    assert np.any(got["geom_id"] == len(scene)) and np.any(got["geom_id"] == len(scene) + 1)


def test_pickle_is_about_the_size_of_the_file(saved):
    scene, _, path, _ = saved
    pickled = pickle.dumps(scene)
    assert abs(len(pickled) - path.stat().st_size) < 256
    geometry = sum(m.vertices.nbytes + m.faces.nbytes + m.nbytes for m in scene._meshes)
    assert len(pickled) < 1.05 * geometry + 64 * 1024  # one copy of each array


def tampered(path, tmp_path, change):
    data = bytearray(path.read_bytes())
    change(data)
    out = tmp_path / "bad.rcs"
    out.write_bytes(bytes(data))
    return out


def header(data):
    _, _, length, _ = struct.unpack_from("<8sIII", data)
    return json.loads(bytes(data[20:20 + length]))


@pytest.mark.parametrize("keep", [0, 7, 19, 100, 0.5, -1])
def test_truncated_file_is_refused(saved, tmp_path, keep):
    _, _, path, _ = saved
    size = path.stat().st_size
    keep = int(size * keep) if isinstance(keep, float) else keep % size
    bad = tampered(path, tmp_path, lambda data: data.__delitem__(slice(keep, None)))
    with pytest.raises(ValueError, match="truncated"):
        Scene.load(bad)


@pytest.mark.parametrize("name", ["objects", "params", "xforms", "top.nodes", "mesh0.nodes",
                                  "mesh0.blocks", "mesh3.faces"])
def test_flipped_bit_in_any_array_is_refused(saved, tmp_path, name):
    _, _, path, _ = saved

    def flip(data):
        info = header(data)
        start = -(-(20 + struct.unpack_from("<I", data, 12)[0]) // arrayfile.ALIGN) * \
            arrayfile.ALIGN
        offset = next(offset for entry, _, _, offset in info["arrays"] if entry == name)
        data[start + offset + 5] ^= 0x10

    # the message names the bytes of the failing checksum's chunk and the arrays in them
    with pytest.raises(ValueError, match=f"fails its checksum in bytes .*'{name}'"):
        Scene.load(tampered(path, tmp_path, flip))


def test_flipped_bit_is_found_in_its_chunk(tmp_path, monkeypatch):
    """A file's data is checked a chunk at a time, on threads for a large file: a flipped bit
    in the third of four chunks is refused, naming that chunk and the one array in it."""
    monkeypatch.setattr(arrayfile, "CHUNK", 4096)
    arrays = {"before": np.arange(1000, dtype=np.int64), "inside": np.ones(1000),
              "after": np.zeros(3, np.float32)}
    path = tmp_path / "chunks.rcs"
    arrayfile.write(path, {"what": "chunks"}, arrays)
    info = header(path.read_bytes())
    assert len(info["crc32"]) == 4  # 8000 + 8000 + 12 bytes, each array on 64 bytes
    for how in ({}, {"mmap": True}):
        meta, read = arrayfile.read(path, **how)
        assert meta == {"what": "chunks"}
        for name, array in arrays.items():
            np.testing.assert_array_equal(read[name], array)
    start = path.stat().st_size - info["data_bytes"]

    def flip(data):
        data[start + 2 * 4096 + 100] ^= 1

    with pytest.raises(ValueError, match="fails its checksum in bytes 8192-12288, which hold "
                                         r"arrays 'inside'\)$"):
        arrayfile.read(tampered(path, tmp_path, flip))
    monkeypatch.setattr(arrayfile, "THREADED_BYTES", 0)  # the threaded read finds it too
    with pytest.raises(ValueError, match="bytes 8192-12288"):
        arrayfile.read(tampered(path, tmp_path, flip))


@pytest.mark.parametrize("version", [1, 2])
def test_files_of_earlier_format_versions_are_still_read(tmp_path, version):
    """Files that raycore wrote in format versions 1 (before the data was checked as one piece)
    and 2 (before the object table was one array and empty tables were left out), of the
    37-object scene of every kind in float32, answer as that scene does when built now: t,
    occlusion and counts, which do not depend on the tree's shape.  Version 1's arrays' own
    checksums still find a flipped bit."""
    path = Path(__file__).parent / "data" / f"every-kind-v{version}.rcs"
    assert struct.unpack_from("<I", path.read_bytes(), 8) == (version,)
    spec, _ = random_scene(3)
    built = spec.scene("float32", max_leaf_size=6, bins=12)
    loaded = Scene.load(path)
    assert len(loaded) == len(built) and loaded.build_params == built.build_params
    assert loaded._visible == built._visible and loaded._kind == built._kind
    origins, directions, tmin, tmax, _ = scene_rays(3)
    np.testing.assert_array_equal(loaded.intersect(origins, directions, tmin, tmax).t,
                                  built.intersect(origins, directions, tmin, tmax).t)
    np.testing.assert_array_equal(loaded.occluded(origins, directions, tmin, tmax),
                                  built.occluded(origins, directions, tmin, tmax))
    np.testing.assert_array_equal(loaded.count(origins, directions, tmin, tmax),
                                  built.count(origins, directions, tmin, tmax))
    if version > 1:
        return

    def flip(data):
        info = header(data)
        start = len(data) - info["data_bytes"]
        entry = next(e for e in info["arrays"] if e["name"] == "mesh0.blocks")
        data[start + entry["offset"] + 5] ^= 0x10

    with pytest.raises(ValueError, match="array 'mesh0.blocks' fails its checksum"):
        Scene.load(tampered(path, tmp_path, flip))


def test_flipped_bit_in_the_header_is_refused(saved, tmp_path):
    _, _, path, _ = saved
    bad = tampered(path, tmp_path, lambda data: data.__setitem__(40, data[40] ^ 1))
    with pytest.raises(ValueError, match="header fails its checksum"):
        Scene.load(bad)


def test_other_files_and_newer_versions_are_refused(saved, tmp_path):
    _, _, path, _ = saved
    other = tmp_path / "other.npy"
    np.save(other, np.zeros(10))
    with pytest.raises(ValueError, match="not a raycore scene file"):
        Scene.load(other)
    newer = tampered(path, tmp_path, lambda data: struct.pack_into(
        "<I", data, 8, arrayfile.VERSION + 1))
    with pytest.raises(ValueError, match="newer than this raycore reads"):
        Scene.load(newer)
    with pytest.raises(ValueError, match="not a raycore scene file"):
        scene_file.load(b"nothing at all here!!")


def test_a_path_that_is_not_a_path_is_refused():
    # an integer would be opened as a file descriptor (and closed): 1 is stdout
    for path in (1, True, None, 2.5):
        with pytest.raises(ValueError, match="path must be a file path"):
            Scene.load(path)


def test_mmap_must_be_a_bool(saved):
    path = saved[2]
    for mmap in (1, "yes", np.array([True, False])):
        with pytest.raises(ValueError, match="mmap must be True or False"):
            Scene.load(path, mmap=mmap)


def test_header_entry_with_an_offset_past_int64_is_refused(saved, tmp_path):
    # a header that passes its checksum but places an array at 2^63 bytes
    _, _, path, _ = saved
    data = path.read_bytes()
    magic, version, length, _ = struct.unpack_from("<8sIII", data)
    header = json.loads(data[20:20 + length])
    header["arrays"][0][3] = 2**63
    text = json.dumps(header).encode()
    prefix = struct.pack("<8sIII", magic, version, len(text), zlib.crc32(text)) + text
    start = -(-(20 + length) // arrayfile.ALIGN) * arrayfile.ALIGN
    bad = tmp_path / "offset.rcs"
    bad.write_bytes(prefix + bytes(-len(prefix) % arrayfile.ALIGN) + data[start:])
    with pytest.raises(ValueError, match="corrupt"):
        Scene.load(bad)


def rewritten(path, tmp_path, change):
    """The file's contents changed by ``change(meta, arrays)`` and written again with valid
    checksums: what a bug or a crafted file could hold."""
    meta, arrays = arrayfile.read(path)
    arrays = {name: array.copy() for name, array in arrays.items()}
    change(meta, arrays)
    out = tmp_path / "crafted.rcs"
    arrayfile.write(out, meta, arrays)
    return out


def _child_slot(nodes):
    """(row, slot) of an internal child in a mesh's wide rows."""
    from raycore.bvh.layout import COUNTS, REFS, WIDTH
    refs = nodes.view(np.int32)
    rows, slots = np.nonzero((refs[:, COUNTS:COUNTS + WIDTH] == 0)
                             & (refs[:, REFS:REFS + WIDTH] > 0))
    return rows[0], REFS + slots[0]


def _leaf_slot(nodes):
    from raycore.bvh.layout import COUNTS, REFS, WIDTH
    refs = nodes.view(np.int32)
    rows, slots = np.nonzero(refs[:, COUNTS:COUNTS + WIDTH] > 0)
    return rows[0], REFS + slots[0]


def loop_to_root(meta, arrays):
    nodes = arrays["mesh4.nodes"]
    row, col = _child_slot(nodes)
    nodes.view(np.int32)[row, col] = 0


def past_the_end(meta, arrays):
    nodes = arrays["mesh4.nodes"]
    row, col = _child_slot(nodes)
    nodes.view(np.int32)[row, col] = len(nodes)


def leaf_past_blocks(meta, arrays):
    nodes = arrays["mesh4.nodes"]
    row, col = _leaf_slot(nodes)
    nodes.view(np.int32)[row, col] = len(arrays["mesh4.blocks"])


def top_leaf_past_slots(meta, arrays):
    nodes = arrays["top.nodes"]
    row, col = _leaf_slot(nodes)
    nodes.view(np.int32)[row, col] = len(arrays["top.slots"])


def unused_slot_entered(meta, arrays):
    nodes = arrays["mesh0.nodes"]
    from raycore.bvh.layout import WIDTH
    unused = np.argwhere(nodes[:, :WIDTH] == np.inf)
    row, slot = unused[0]
    nodes[row, slot] = 0.0  # a box that rays can enter, around a reference to the root


CRAFTED = {
    "internal child back to the root": loop_to_root,
    "internal child past the last row": past_the_end,
    "leaf past the mesh's blocks": leaf_past_blocks,
    "top-tree leaf past its objects": top_leaf_past_slots,
    "unused slot that rays can enter": unused_slot_entered,
    "unknown object kind": lambda m, a: a["objects"].__setitem__((0, 0), 99),
    "mesh reference out of range": lambda m, a: a["objects"].__setitem__(
        (int(np.flatnonzero(a["objects"][:, 0] == 16)[0]), 2), 999),
    "parameter row out of range": lambda m, a: a["objects"].__setitem__((0, 1), 10**6),
    "transform row out of range": lambda m, a: a["objects"].__setitem__(
        (int(np.flatnonzero(a["objects"][:, 3] >= 0)[0]), 3), 10**6),
    "visibility flag other than 0 and 1": lambda m, a: a["objects"].__setitem__((0, 4), 2),
    "face index out of range": lambda m, a: a["mesh0.faces"].__setitem__((0, 0), 10**6),
    "slot face out of range": lambda m, a: face_ints(a["mesh0.blocks"]).__setitem__(
        (0, FACE_COLUMN), 10**6),
    "direct object out of range": lambda m, a: a["top.direct"].__setitem__(0, 10**6),
    "missing table": lambda m, a: a.pop("params"),
    "missing array": lambda m, a: a.pop("mesh2.blocks"),
    "wrong dtype": lambda m, a: a.__setitem__("objects", a["objects"].astype(np.int32)),
    "wrong shape": lambda m, a: a.__setitem__("mesh1.blocks", a["mesh1.blocks"][:, :5].copy()),
    "other layout": lambda m, a: m["layout"].__setitem__("node_width", 32),
    "missing meta": lambda m, a: m.pop("meshes"),
}


@pytest.mark.parametrize("case", CRAFTED)
def test_crafted_file_with_valid_checksums_is_refused(saved, tmp_path, case):
    _, _, path, _ = saved
    bad = rewritten(path, tmp_path, CRAFTED[case])
    with pytest.raises(ValueError, match="scene file"):
        Scene.load(bad)


def test_deep_chain_is_refused(tmp_path):
    """A tree deeper than the traversal's stack allows (each row one internal child)."""
    from raycore.bvh.build import MAX_DEPTH
    from raycore.bvh.layout import COUNTS, NODE_WIDTH, REFS, WIDTH
    scene = Scene()
    scene.add_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    scene.save(tmp_path / "one.rcs")

    def chain(meta, arrays):
        rows = MAX_DEPTH + 1
        nodes = np.zeros((rows, NODE_WIDTH), np.float32)
        nodes[:, :3 * WIDTH] = np.inf
        nodes[:, 3 * WIDTH:6 * WIDTH] = -np.inf
        nodes[:, [0, WIDTH, 2 * WIDTH]] = 0.0
        nodes[:, [3 * WIDTH, 4 * WIDTH, 5 * WIDTH]] = 1.0
        refs = nodes.view(np.int32)
        refs[:, REFS:] = 0
        refs[:-1, REFS] = np.arange(1, rows)
        refs[-1, COUNTS] = 1
        arrays["mesh0.nodes"] = nodes

    with pytest.raises(ValueError, match="deeper than"):
        Scene.load(rewritten(tmp_path / "one.rcs", tmp_path, chain))


def test_save_is_atomic_and_leaves_no_temporary(tmp_path):
    scene = Scene()
    scene.add_sphere([0, 0, 0], 1.0)
    scene.save(tmp_path / "a.rcs")
    scene.add_sphere([3, 0, 0], 1.0)
    scene.save(tmp_path / "a.rcs")  # replaces it
    assert [p.name for p in tmp_path.iterdir()] == ["a.rcs"]
    assert len(Scene.load(tmp_path / "a.rcs")) == 2


@pytest.mark.parametrize("cut", [None, 0.5, -1])
def test_threaded_read_in_pieces(saved, tmp_path, monkeypatch, cut):
    """A large file's path (pieces read and checksummed on threads), taken with small chunks so
    that this file has many: the same answers, or "truncated" for a cut copy."""
    scene, expected, _, rays = saved
    monkeypatch.setattr(arrayfile, "CHUNK", 4096)  # written and read with 4 KiB chunks
    monkeypatch.setattr(arrayfile, "THREADED_BYTES", 0)
    monkeypatch.setattr(arrayfile, "get_num_threads", lambda: 2)
    path = tmp_path / "pieces.rcs"
    scene.save(path)
    if cut is not None:
        size = path.stat().st_size
        path = tampered(path, tmp_path, lambda data: data.__delitem__(
            slice(int(size * cut) % size, None)))
        with pytest.raises(ValueError, match="truncated"):
            Scene.load(path)
        return
    got = answers(Scene.load(path), rays)
    for name, value in expected.items():
        np.testing.assert_array_equal(got[name], value, err_msg=name)


def test_loading_compiles_one_mesh_check_for_every_mesh(tmp_path):
    """A mesh of one leaf block and one of many, in both dtypes, reach the same compiled mesh
    check: a service that loads scenes from its data directory compiles nothing that
    ``raycore warmup`` did not (a one-block mesh's face columns, sliced, were typed apart)."""
    bunny = shared_mesh("stanford-bunny")
    for dtype in ("float32", "float64"):
        for vertices, faces in (([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]),
                                (bunny.vertices, bunny.faces)):
            scene = Scene(dtype)
            scene.add_mesh(vertices, faces)
            scene.save(tmp_path / "one.rcs")
            Scene.load(tmp_path / "one.rcs")
    assert len(scene_file._mesh_problem.signatures) == 1
    assert len(scene_file._object_problem.signatures) == 1
