"""A small OpenVDB writer for the bake: dense float and vec3s grids, plus grids copied verbatim.

libvolscatter writes the scattering grid in world space as three float grids; a USD field needs
its grid in the Volume prim's *local* space, in one file with the other fields (Blender's USD
importer reads one file per Volume), and one RGB grid `scatter`. The layout mirrors volscatter's
own float writer (core/src/vdb/writer.rs, checked against OpenVDB): file version 224, Zip with the
active-mask flag, an AffineMap, a 5-4-3 tree of dense leaves where a voxel is active when any
component is non-zero. A grid of another version-224 file (the density) is copied byte for byte
with new offsets: a grid's data holds no absolute file offsets. Checked against pyopenvdb in
tests/python/test_usd_stage.py and test_usd_host.py.
"""

from __future__ import annotations

import struct
import uuid
import zlib
from typing import Sequence

import numpy as np

FILE_VERSION = 224
COMPRESS_ZIP = 0x1
COMPRESS_ACTIVE_MASK = 0x2


class _W:
    def __init__(self):
        self.parts = []
        self.n = 0

    def bytes(self, b: bytes):
        self.parts.append(b)
        self.n += len(b)

    def u8(self, v):
        self.bytes(struct.pack("<B", v))

    def u32(self, v):
        self.bytes(struct.pack("<I", v))

    def i32(self, v):
        self.bytes(struct.pack("<i", v))

    def i64(self, v):
        self.bytes(struct.pack("<q", v))

    def string(self, s: str):
        b = s.encode()
        self.u32(len(b))
        self.bytes(b)

    def mask(self, words: np.ndarray):
        self.bytes(np.asarray(words, dtype="<u8").tobytes())

    def placeholder_i64x3(self):
        self.parts.append(None)
        at = len(self.parts) - 1
        self.n += 24
        return at

    def patch(self, at, a, b, c):
        self.parts[at] = struct.pack("<3q", a, b, c)

    def value(self):
        return b"".join(self.parts)


def _block(w: _W, active_values: np.ndarray):
    """Values of one node with the active-mask flag: metadata 0 (inactive values are the
    background), then the active values, Zip-compressed when that is smaller."""
    w.u8(0)
    raw = np.ascontiguousarray(active_values, dtype="<f4").tobytes()
    z = zlib.compress(raw) if raw else b""
    if z and len(z) < len(raw):
        w.i64(len(z))
        w.bytes(z)
    else:
        w.i64(-len(raw))
        w.bytes(raw)


def _bits(flags: np.ndarray) -> np.ndarray:
    """bool array (n, multiple of 64) -> little-endian u64 words (bit i of word i >> 6)."""
    f = flags.reshape(-1, 64).astype(np.uint64)
    return (f << np.arange(64, dtype=np.uint64)).sum(axis=1, dtype=np.uint64)


def _tree(a: np.ndarray):
    """Leaves of a (nz, ny, nx, C) array: {i5 origin: {i4: {i3: (mask words, active values)}}}."""
    nz, ny, nx, c = a.shape
    pz, py, px = (-nz) % 8, (-ny) % 8, (-nx) % 8
    xyz = np.pad(a, ((0, pz), (0, py), (0, px), (0, 0))).transpose(2, 1, 0, 3)  # (X, Y, Z, C)
    X, Y, Z = xyz.shape[:3]
    nodes = {}
    voxels = 0
    lo = [1 << 30] * 3
    hi = [-(1 << 30)] * 3
    for bx in range(0, X, 8):
        for by in range(0, Y, 8):
            for bz in range(0, Z, 8):
                leaf = xyz[bx:bx + 8, by:by + 8, bz:bz + 8].reshape(512, c)  # index (x<<6)|(y<<3)|z
                act = (leaf != 0).any(axis=1)
                if not act.any():
                    continue
                idx = np.nonzero(act)[0]
                voxels += len(idx)
                pts = np.stack([bx + (idx >> 6), by + ((idx >> 3) & 7), bz + (idx & 7)], axis=1)
                lo = [min(lo[k], int(pts[:, k].min())) for k in range(3)]
                hi = [max(hi[k], int(pts[:, k].max())) for k in range(3)]
                o = (bx, by, bz)
                o5 = tuple(v & ~4095 for v in o)
                i4 = (((o[0] & 4095) >> 7) << 10) | (((o[1] & 4095) >> 7) << 5) | ((o[2] & 4095) >> 7)
                i3 = (((o[0] & 127) >> 3) << 8) | (((o[1] & 127) >> 3) << 4) | ((o[2] & 127) >> 3)
                nodes.setdefault(o5, {}).setdefault(i4, {})[i3] = (_bits(act), leaf[act])
    return nodes, voxels, lo, hi


def _write_meta(w: _W, meta):
    w.u32(len(meta))
    for k, ty, v in meta:
        w.string(k)
        w.string(ty)
        if ty == "string":
            w.string(v)
        elif ty == "bool":
            w.u32(1)
            w.u8(int(v))
        elif ty == "int64":
            w.u32(8)
            w.i64(v)
        elif ty == "vec3i":
            w.u32(12)
            w.bytes(struct.pack("<3i", *v))


def _write_grid(w: _W, name: str, a: np.ndarray, m: np.ndarray):
    """Descriptor and body of one float (C = 1) or vec3s (C = 3) grid."""
    comps = a.shape[3]
    nodes, voxels, lo, hi = _tree(a)
    w.string(name)
    w.string("Tree_float_5_4_3" if comps == 1 else "Tree_vec3s_5_4_3")
    w.string("")
    offsets = w.placeholder_i64x3()
    grid_pos = w.n
    w.u32(COMPRESS_ACTIVE_MASK | COMPRESS_ZIP)
    meta = [("class", "string", "fog volume" if comps == 1 else "unknown"), ("name", "string", name)]
    if comps == 3:
        meta.append(("vector_type", "string", "invariant"))
    meta += [("is_saved_as_half_float", "bool", False), ("file_voxel_count", "int64", voxels),
             ("creator", "string", "volscatter-usd")]
    if voxels:
        meta += [("file_bbox_min", "vec3i", lo), ("file_bbox_max", "vec3i", hi)]
    _write_meta(w, meta)
    # transform: AffineMap, OpenVDB's row-vector Mat4d = our column-vector matrix transposed
    w.string("AffineMap")
    w.bytes(np.ascontiguousarray(m.T, dtype="<f8").tobytes())
    # topology
    w.i32(1)  # buffer count
    w.bytes(np.zeros(comps, "<f4").tobytes())  # background
    w.u32(0)  # root tiles
    w.u32(len(nodes))
    empty = np.zeros((0, comps), np.float32)
    for o5 in sorted(nodes):
        w.bytes(struct.pack("<3i", *o5))
        child = np.zeros(32768, bool)
        child[list(nodes[o5].keys())] = True
        w.mask(_bits(child))
        w.mask(np.zeros(512, np.uint64))
        _block(w, empty)
        for i4 in sorted(nodes[o5]):
            leaves = nodes[o5][i4]
            child = np.zeros(4096, bool)
            child[list(leaves.keys())] = True
            w.mask(_bits(child))
            w.mask(np.zeros(64, np.uint64))
            _block(w, empty)
            for i3 in sorted(leaves):
                w.mask(leaves[i3][0])
    block_pos = w.n
    for o5 in sorted(nodes):
        for i4 in sorted(nodes[o5]):
            for i3 in sorted(nodes[o5][i4]):
                words, vals = nodes[o5][i4][i3]
                w.mask(words)
                _block(w, vals)
    w.patch(offsets, grid_pos, block_pos, w.n)
    return voxels


def _find_grid(path, name: str):
    """(version, type, grid bytes [grid_pos, end_pos), block offset) of the first grid named
    ``name`` in an OpenVDB file, or None when it cannot be copied (not version 224, instanced,
    no offsets)."""
    with open(path, "rb") as f:
        data = f.read()
    pos = 0

    def take(n):
        nonlocal pos
        if pos + n > len(data):
            raise ValueError("truncated")
        b = data[pos:pos + n]
        pos += n
        return b

    def u32():
        return struct.unpack("<I", take(4))[0]

    def string():
        return take(u32()).decode("utf-8", "replace")

    try:
        if take(8) != struct.pack("<Q", 0x56444220):
            return None
        version = u32()
        take(8)
        has_offsets = take(1)[0]
        take(36)
        for _ in range(u32()):
            string()
            string()
            take(u32())
        for _ in range(u32()):
            gname = string()
            gtype = string()
            parent = string()
            if not has_offsets:
                return None
            gpos, bpos, epos = struct.unpack("<3q", take(24))
            if gname.split("\x1e")[0] == name:
                if version != FILE_VERSION or parent or not (0 < gpos <= bpos <= epos <= len(data)):
                    return None
                return version, gtype, data[gpos:epos], bpos - gpos
            pos = epos
    except (ValueError, struct.error):
        return None
    return None


def write_grids(path, grids, index_to_world: Sequence[float], copy=()):
    """Writes float / vec3s grids sharing one index-to-world map (16 floats, row-major, column
    vectors): ``grids`` = [(name, array (nz, ny, nx, C) with C 1 or 3; voxel (i, j, k) =
    a[k, j, i])], plus grids copied verbatim from other version-224 files: ``copy`` =
    [(name, source path, source grid name)]. Returns the names of the copied grids (a grid that
    cannot be copied is left out)."""
    m = np.asarray(index_to_world, dtype=np.float64).reshape(4, 4)
    if not np.isfinite(m).all() or abs(np.linalg.det(m[:3, :3])) == 0:
        raise ValueError("index-to-world map is not invertible")
    arrays = []
    for name, a in grids:
        a = np.asarray(a, dtype=np.float32)
        if a.ndim == 3:
            a = a[..., None]
        if a.ndim != 4 or a.shape[3] not in (1, 3):
            raise ValueError(f"{name}: expected an (nz, ny, nx, 1 or 3) array, got {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"{name}: non-finite values")
        arrays.append((name, a))
    copies = []
    for name, src, src_name in copy:
        found = _find_grid(src, src_name)
        if found is not None:
            copies.append((name, found))
    w = _W()
    w.bytes(struct.pack("<Q", 0x56444220))
    w.u32(FILE_VERSION)
    w.u32(10)
    w.u32(0)
    w.u8(1)  # grid offsets present
    w.bytes(str(uuid.uuid4()).encode())
    _write_meta(w, [("creator", "string", "volscatter-usd")])
    w.i32(len(arrays) + len(copies))
    for name, (_v, gtype, body, block_off) in copies:
        w.string(name)
        w.string(gtype)
        w.string("")
        offsets = w.placeholder_i64x3()
        gpos = w.n
        w.bytes(body)
        w.patch(offsets, gpos, gpos + block_off, w.n)
    for name, a in arrays:
        _write_grid(w, name, a, m)
    with open(path, "wb") as f:
        f.write(w.value())
    return [name for name, _ in copies]


def write_vec3_grid(path, name: str, rgb: np.ndarray, index_to_world: Sequence[float]):
    """Writes ``rgb`` (nz, ny, nx, 3; voxel (i, j, k) = rgb[k, j, i]) as one vec3s grid ``name``
    whose voxel (i, j, k) sits at ``index_to_world`` (16 floats, row-major 4x4, column vectors).
    Returns the number of active voxels."""
    a = np.asarray(rgb, dtype=np.float32)
    if a.ndim != 4 or a.shape[3] != 3:
        raise ValueError(f"expected an (nz, ny, nx, 3) array, got {a.shape}")
    write_grids(path, [(name, a)], index_to_world)
    return int((a != 0).any(axis=3).sum())
