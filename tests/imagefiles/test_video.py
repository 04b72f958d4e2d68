"""The H.264 writer: the same frames give the same file, whatever the process did before."""

from __future__ import annotations

import hashlib
import sys

import numpy as np
import pytest

from splatgl.imagefiles import video

AVX512_FLAGS = ("flags\t\t: fpu sse sse2 pni ssse3 sse4_1 sse4_2 avx fma bmi1 bmi2 avx2 abm "
                "avx512f avx512dq avx512cd avx512bw avx512vl\n")
AVX2_FLAGS = "flags\t\t: fpu sse sse2 pni ssse3 sse4_1 sse4_2 avx fma bmi1 bmi2 avx2 abm\n"


def test_x264_is_capped_below_avx512_only_where_the_cpu_has_it():
    assert video.x264_asm(AVX512_FLAGS) == "MMX2,SSE,SSE2,SSE3,SSSE3,SSE4.1,SSE4.2,AVX,FMA3,BMI1,BMI2,AVX2,LZCNT"
    assert video.x264_asm(AVX2_FLAGS) is None          # x264's own detection, untouched
    assert video.x264_asm("Features\t: fp asimd evtstrm\n") is None   # Arm


def _frames() -> list[np.ndarray]:
    """Six smooth 96x64 RGBA frames of a moving pattern (as a camera path gives)."""
    yy, xx = np.mgrid[0:64, 0:96].astype(np.float32)
    out = []
    for k in range(6):
        rgb = np.stack([np.sin((xx + 3 * k) / 9), np.cos((yy - 2 * k) / 7),
                        np.sin((xx + yy + k) / 12)], -1) * 0.5 + 0.5
        blob = np.exp(-((xx - 30 - 4 * k) ** 2 + (yy - 32) ** 2) / 60)[..., None]
        out.append(np.concatenate([rgb * (1 - blob) + blob, np.ones_like(blob)], -1).astype(np.float32))
    return out


def _churn(seed: int) -> None:
    """Fill and free heap blocks of many sizes with random bytes, so that memory an encoder reads
    without writing holds something different on each pass."""
    rng = np.random.default_rng(seed)
    blocks = [rng.integers(0, 256, int(n), dtype=np.uint8) for n in rng.integers(1_000, 200_000, 300)]
    del blocks


@pytest.mark.slow
def test_same_frames_same_video_bytes(tmp_path):
    """Fails without the AVX-512 cap on a CPU that has AVX-512 (measured: 3 of 10 encodes
    differed); passes trivially elsewhere, where x264 is left alone."""
    pytest.importorskip("av")
    frames = _frames()
    digests = set()
    for k in range(16):
        path = tmp_path / f"v{k}.mp4"
        with video.VideoWriter(path, 96, 64, fps=30) as writer:
            for frame in frames:
                writer.write(frame)
        digests.add(hashlib.sha256(path.read_bytes()).hexdigest())
        _churn(k)
    assert len(digests) == 1, f"{len(digests)} different videos from the same frames"


def test_writer_checks_its_arguments_before_it_needs_pyav(tmp_path, monkeypatch):
    """Without PyAV the writer still names a wrong suffix or size (they are wrong with it too);
    only valid arguments get the install hint.  Nothing is written."""
    from splatgl.errors import SplatglError

    monkeypatch.setitem(sys.modules, "av", None)     # import av fails
    for args, message in [((tmp_path / "v.avi", 96, 64), "video output must end in"),
                          ((tmp_path / "v.mp4", 95, 64), "needs an even width and height, got 95x64"),
                          ((tmp_path / "v.mp4", 96, 64), "video output needs PyAV")]:
        with pytest.raises(SplatglError, match=message):
            video.VideoWriter(*args)
    assert list(tmp_path.iterdir()) == []


def test_a_stopped_sharded_video_names_its_frames_or_leaves_nothing(tmp_path):
    """After Ctrl-C or SIGTERM with workers: a hidden frames folder holding complete frames is
    kept for --resume and named in one line; one holding none (only a temporary) is removed."""
    from splatgl.tasks.render_tasks import frame_folder, stopped_video_note

    video = tmp_path / "v.mp4"
    assert stopped_video_note(video) is None                      # no folder at all
    folder = frame_folder(video)
    folder.mkdir()
    (folder / ".00003.partial12.png").write_bytes(b"half")       # a worker's temporary
    assert stopped_video_note(video) is None and not folder.exists()
    folder.mkdir()
    (folder / "00000.png").write_bytes(b"x")
    assert stopped_video_note(video) == (
        f"1 frame kept in the hidden folder {folder}/ (no video written): re-run with --resume "
        f"and workers (--workers N or --executor ray) to render the rest and write {video}, or "
        "delete the folder")
    assert folder.is_dir()
