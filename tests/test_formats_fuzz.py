"""Truncated and corrupted compressed PLY / SPZ / ksplat files: load or SceneFormatError, fast.

Seeded: each file gets the same truncation lengths and byte corruptions every run.  A case
passes when the loader returns a scene or raises :class:`SceneFormatError` within
``CASE_SECONDS``; any other exception (IndexError, zlib.error, ValueError from NumPy...) or a
slow case fails.  The big real files get fewer cases to keep the whole module near 10 s.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from splatgl.errors import SceneFormatError
from splatgl.formats import compressed_ply, ksplat, spz

from test_formats_compressed import _spz_body, write_ksplat  # synthetic writers (same folder)

#: Longest one load of a damaged file may take (seconds).
CASE_SECONDS = 5.0

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


def truncations(size: int, cases: int, rng) -> list[int]:
    """Fixed lengths (empty, magic only, header-sized) and ``cases`` random ones, all < size."""
    fixed = [0, 1, 4, 15, 16, 100, size // 2, size - 1]
    return sorted({n for n in fixed if n < size} | set(rng.integers(0, size, cases).tolist()))


def corruptions(data: bytes, cases: int, rng) -> list[bytes]:
    """Copies of ``data`` with 1-8 random bytes replaced, in the first 256 bytes (headers) for
    half of the cases and anywhere for the rest; plus one with a 0xff run over a header count."""
    out = []
    for case in range(2 * cases):
        buf = bytearray(data)
        span = min(len(buf), 256) if case % 2 == 0 else len(buf)
        for pos in rng.integers(0, span, rng.integers(1, 9)):
            buf[pos] = int(rng.integers(0, 256))
        out.append(bytes(buf))
    for start in (8, 12):  # SPZ numPoints / ksplat counts / PLY header text
        buf = bytearray(data)
        buf[start:start + 4] = b"\xff\xff\xff\xff"
        out.append(bytes(buf))
    return out


def check_case(read, path, data: bytes, what: str) -> None:
    path.write_bytes(data)
    start = time.perf_counter()
    try:
        read(path)
    except SceneFormatError:
        pass
    except Exception as exc:  # noqa: BLE001 - the point of the test
        pytest.fail(f"{what}: {type(exc).__name__}: {exc}")
    took = time.perf_counter() - start
    assert took < CASE_SECONDS, f"{what}: took {took:.1f} s"


@pytest.mark.parametrize("name,read,cases", FILES, ids=[f[0] for f in FILES])
def test_truncated_and_corrupted_files(shared_scenes, tmp_path, name, read, cases):
    data = (shared_scenes / name).read_bytes()
    path = tmp_path / ("damaged" + "".join(shared_scenes.joinpath(name).suffixes))
    rng = np.random.default_rng(sum(data[:64]) + len(data))
    for length in truncations(len(data), cases, rng):
        check_case(read, path, data[:length], f"{name} cut to {length} bytes")
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
        check_case(read, path, data[:length], f"{kind} cut to {length} bytes")
    for i, damaged in enumerate(corruptions(data, 10, rng)):
        check_case(read, path, damaged, f"{kind} corruption {i}")
