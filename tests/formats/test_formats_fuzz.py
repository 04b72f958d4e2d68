"""Truncated and corrupted compressed PLY / SPZ / ksplat files: load or SceneFormatError, in
bounded memory.

Seeded: each file gets the same truncation lengths and byte corruptions every run.  A
truncated file must fail; a corrupted one passes when the loader returns a scene or raises
:class:`SceneFormatError` with one printable line of bounded length, printing no NumPy warning
and peaking at no more memory than the file's size allows (``helpers.check_case``); any other
exception (IndexError, zlib.error, ValueError from NumPy...) fails.  The big real files get
fewer cases to keep the whole module near 10 s.

Then the damage random bytes rarely produce, each of which once loaded as garbage with exit 0
(issue 17): gzip streams with bytes deleted or the trailer cut, header counts off by one,
property types changed, header fields out of range, a version 4 SPZ relabelled version 3.
These must fail, with the message naming the field.
"""

from __future__ import annotations

import gzip
import struct

import numpy as np
import pytest

from splatgl.formats import compressed_ply, ksplat, spz

from helpers import check_case, corruptions, truncations
from test_formats_compressed import _spz_body, write_ksplat  # synthetic writers (same folder)

#: (file, reader, cases per kind); big files get fewer cases.
FILES = [
    ("compressed_ply/biker.compressed.ply", compressed_ply.read, 3),
    ("compressed_ply/guitar.compressed.ply", compressed_ply.read, 2),
    ("fixtures/test64_sh3.compressed.ply", compressed_ply.read, 10),
    ("spz/biker_v4.spz", spz.read, 3),
    ("spz/donut_sh0_v2.spz", spz.read, 4),
    ("fixtures/minimal-v2.spz", spz.read, 10),
    ("fixtures/minimal-v3.spz", spz.read, 10),
    ("fixtures/minimal-v4.spz", spz.read, 10),
    ("fixtures/minimal-raw.spz", spz.read, 10),
    ("fixtures/minimal.ksplat", ksplat.read, 10),
]


@pytest.mark.parametrize("name,read,cases", FILES, ids=[f[0] for f in FILES])
def test_truncated_and_corrupted_files(shared_scenes, tmp_path, name, read, cases):
    data = (shared_scenes / name).read_bytes()
    path = tmp_path / ("damaged" + "".join(shared_scenes.joinpath(name).suffixes))
    rng = np.random.default_rng(sum(data[:64]) + len(data))
    for length in truncations(len(data), cases, rng):  # every format knows its end
        check_case(read, path, data[:length], f"{name} cut to {length} bytes", must_fail=True)
    for i, damaged in enumerate(corruptions(data, cases, rng)):
        check_case(read, path, damaged, f"{name} corruption {i}")


@pytest.mark.parametrize("kind", ["ksplat-1", "ksplat-2", "spz-v3-sh2", "spz-v2-sh3"])
def test_damaged_synthetic_files(tmp_path, kind):
    """Cases no real file covers: ksplat levels 1-2 (float16, buckets) and SPZ with SH."""
    import gzip

    rng = np.random.default_rng(len(kind))
    src = tmp_path / ("src.ksplat" if kind.startswith("ksplat") else "src.spz")
    if kind.startswith("ksplat"):
        n = 10
        q = rng.normal(size=(n, 4))
        write_ksplat(src, int(kind[-1]), rng.uniform(-1, 1, (n, 3)), rng.uniform(0.01, 1, (n, 3)),
                     q / np.linalg.norm(q, axis=1, keepdims=True),
                     rng.integers(0, 256, (n, 4), dtype=np.uint8), rng.uniform(-1, 1, (n, 24)))
        read = ksplat.read
    else:
        body, _ = _spz_body(int(kind[5]), 7, int(kind[-1]), rng)
        src.write_bytes(gzip.compress(body))
        read = spz.read
    data = src.read_bytes()
    read(src)  # the undamaged file loads
    path = tmp_path / ("damaged" + src.suffix)
    for length in truncations(len(data), 10, rng):
        check_case(read, path, data[:length], f"{kind} cut to {length} bytes", must_fail=True)
    for i, damaged in enumerate(corruptions(data, 10, rng)):
        check_case(read, path, damaged, f"{kind} corruption {i}")


# --- damage that once loaded as garbage (issue 17) --------------------------------------------


def spz_file(version: int, count: int = 7, sh_degree: int = 1, gz: bool = True) -> bytes:
    body, _ = _spz_body(version, count, sh_degree, np.random.default_rng(version + count))
    return gzip.compress(body, mtime=0) if gz else body


def spz_header(body: bytes, **fields) -> bytes:
    """``body`` (raw, header first) with header fields replaced."""
    names = ["magic", "version", "numPoints", "shDegree", "fractionalBits", "flags", "reserved"]
    values = dict(zip(names, struct.unpack_from(spz.HEADER_FORMAT, body)))
    values.update(fields)
    return struct.pack(spz.HEADER_FORMAT, *values.values()) + body[spz.HEADER_BYTES:]


def expect_failure(tmp_path, data: bytes, what: str, *fragments: str, suffix=".spz",
                   read=None) -> str:
    path = tmp_path / f"case{suffix}"
    message = check_case(read or (spz.read if suffix == ".spz" else compressed_ply.read),
                         path, data, what, must_fail=True)
    for fragment in fragments:
        assert fragment in message, f"{what}: {fragment!r} not in {message!r}"
    return message


def test_spz_gzip_trailer_and_deleted_bytes_are_caught(tmp_path):
    data = spz_file(3)
    rng = np.random.default_rng(17)
    for cut in (1, 4, 5, 8):  # inside the ISIZE field, at the CRC, inside it
        expect_failure(tmp_path, data[:-cut], f"trailer cut by {cut}", "truncated")
    for pos, name in ((len(data) - 8, "CRC-32"), (len(data) - 4, "length")):
        buf = bytearray(data)
        buf[pos] ^= 0x01
        expect_failure(tmp_path, bytes(buf), f"{name} byte flipped", name)
    body_start, body_end = 10, len(data) - 8  # gzip header (no name) and trailer
    for _ in range(12):
        at = int(rng.integers(body_start + 4, body_end - 1))
        n = int(rng.integers(1, 4))
        expect_failure(tmp_path, data[:at] + data[at + n:], f"{n} bytes deleted at {at}")
    expect_failure(tmp_path, data + b"\0" * 4, "bytes after the stream", "after the end")


@pytest.mark.parametrize("version,gz", [(1, True), (2, True), (3, True), (2, False), (3, False)])
def test_spz_num_points_off_by_one(tmp_path, version, gz):
    body, _ = _spz_body(version, 7, 1, np.random.default_rng(version))
    for count in (6, 8):
        damaged = spz_header(body, numPoints=count)
        data = gzip.compress(damaged, mtime=0) if gz else damaged
        expect_failure(tmp_path, data, f"v{version} numPoints {count}", "numPoints")


def test_spz_v4_num_points_and_relabel(tmp_path, shared_scenes):
    data = (shared_scenes / "fixtures/minimal-v4.spz").read_bytes()
    for count in (3, 5):
        damaged = data[:8] + struct.pack("<I", count) + data[12:]
        expect_failure(tmp_path, damaged, f"v4 numPoints {count}", "expected")
    for version in (1, 2, 3):  # a version 4 container relabelled: its body does not fit
        expect_failure(tmp_path, data[:4] + struct.pack("<I", version) + data[8:],
                       f"v4 relabelled v{version}")
    expect_failure(tmp_path, data + b"\0", "v4 with a byte appended", "follow the stream table")
    for streams in (4, 6):
        expect_failure(tmp_path, data[:15] + bytes([streams]) + data[16:],
                       f"v4 with {streams} streams", "numStreams")
    expect_failure(tmp_path, gzip.compress(data, mtime=0), "v4 gzipped", "version 4")


@pytest.mark.parametrize("field,value,fragment", [
    ("fractionalBits", 24, "fractionalBits"), ("fractionalBits", 31, "fractionalBits"),
    ("fractionalBits", 255, "fractionalBits"), ("flags", 0x04, "unknown bits 0x04"),
    ("flags", 0x80, "unknown bits 0x80"), ("reserved", 1, "reserved"),
    ("shDegree", 4, "shDegree"), ("version", 5, "version"), ("magic", b"NGSQ", "magic"),
])
def test_spz_header_fields_are_bounded(tmp_path, field, value, fragment):
    body, _ = _spz_body(3, 7, 0, np.random.default_rng(0))
    damaged = spz_header(body, **{field: value})
    for data, how in ((gzip.compress(damaged, mtime=0), "gzip"), (damaged, "raw")):
        expect_failure(tmp_path, data, f"{field}={value} ({how})", fragment)


def test_spz_fractional_bits_at_the_bound_still_loads(tmp_path):
    path = tmp_path / "f23.spz"
    body, _ = _spz_body(3, 7, 0, np.random.default_rng(0))
    path.write_bytes(gzip.compress(spz_header(body, fractionalBits=spz.MAX_FRACTIONAL_BITS)))
    assert np.abs(spz.read(path).means).max() < 1.0


# compressed PLY: a small synthetic file whose header the cases rewrite

CHUNK_PROPS = ["min_x", "min_y", "min_z", "max_x", "max_y", "max_z", "min_scale_x",
               "min_scale_y", "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z"]
PACKED = ["packed_position", "packed_rotation", "packed_scale", "packed_color"]


def compressed_ply_file(n: int = 300, n_rest: int = 9, chunk_type: str = "float",
                        packed_type: str = "uint", counts: dict | None = None,
                        sh_props: bool = True, bound: float | None = None) -> bytes:
    """A valid compressed PLY of ``n`` splats (body always written for the true counts); the
    arguments change only what the header says, or one chunk bound's value."""
    rng = np.random.default_rng(n)
    chunks = -(-n // 256)
    bounds = np.tile(np.array([-1, -1, -1, 1, 1, 1, -5, -5, -5, -2, -2, -2], "<f4"), (chunks, 1))
    if bound is not None:
        bounds[chunks - 1, 4] = bound
    counts = {"chunk": chunks, "vertex": n, "sh": n, **(counts or {})}
    head = ["ply", "format binary_little_endian 1.0", f"element chunk {counts['chunk']}"]
    head += [f"property {chunk_type} {p}" for p in CHUNK_PROPS]
    head += [f"element vertex {counts['vertex']}"] + [f"property {packed_type} {p}" for p in PACKED]
    if n_rest:
        head.append(f"element sh {counts['sh']}")
        if sh_props:
            head += [f"property uchar f_rest_{i}" for i in range(n_rest)]
    head.append("end_header\n")
    body = [bounds.tobytes(), rng.integers(0, 2**32, (n, 4), dtype="<u4").tobytes()]
    if n_rest:
        body.append(rng.integers(0, 256, (n, n_rest), dtype="u1").tobytes())
    return "\n".join(head).encode() + b"".join(body)


def test_compressed_ply_synthetic_loads(tmp_path):
    path = tmp_path / "ok.compressed.ply"
    path.write_bytes(compressed_ply_file())
    assert compressed_ply.read(path).count == 300


@pytest.mark.parametrize("element,delta", [("chunk", -1), ("chunk", 1), ("vertex", -1),
                                           ("vertex", 1), ("sh", -1), ("sh", 1)])
def test_compressed_ply_count_off_by_one(tmp_path, element, delta):
    count = {"chunk": 2, "vertex": 300, "sh": 300}[element] + delta
    expect_failure(tmp_path, compressed_ply_file(counts={element: count}),
                   f"{element} {count}", suffix=".compressed.ply")


@pytest.mark.parametrize("kw,fragment", [
    ({"chunk_type": "double"}, "truncated"), ({"chunk_type": "uint"}, "expected float"),
    ({"chunk_type": "half"}, "unknown type"), ({"packed_type": "ushort"}, "bytes after"),
    ({"packed_type": "int"}, "expected unsigned"), ({"packed_type": "float"}, "expected unsigned"),
])
def test_compressed_ply_property_type_changed(tmp_path, kw, fragment):
    expect_failure(tmp_path, compressed_ply_file(**kw), str(kw), fragment,
                   suffix=".compressed.ply")


def test_compressed_ply_sh_element_without_properties(tmp_path):
    expect_failure(tmp_path, compressed_ply_file(sh_props=False), "element sh, no properties",
                   "declares no properties", suffix=".compressed.ply")


@pytest.mark.parametrize("value", [np.inf, -np.inf, np.nan])
def test_compressed_ply_non_finite_chunk_bound_names_chunk_and_field(tmp_path, value):
    expect_failure(tmp_path, compressed_ply_file(bound=value), f"bound {value}",
                   "field 'max_y'", "chunk 1 (of 2)", suffix=".compressed.ply")
