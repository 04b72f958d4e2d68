"""``--workers N``: local processes on contiguous chunks give the same files as one process."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import numpy as np
import pytest

from helpers import signal_and_wait, start_gated, summary_counts
from splatgl.cli import main
from splatgl.commands._common import demo_scene_path
from splatgl.imagefiles.images import read_image
from splatgl.tasks.render_tasks import frame_folder
from splatgl.tasks.task import KILL_ONCE_ENV
from splatgl.tasks.local import chunks


pytestmark = pytest.mark.slow  # each run spawns worker processes


def test_chunks_are_contiguous_and_cover():
    assert chunks(10, 3) == [range(0, 3), range(3, 7), range(7, 10)]
    assert chunks(2, 4) == [range(0, 1), range(1, 2)]
    assert [i for c in chunks(17, 5) for i in c] == list(range(17))


def test_two_workers_write_the_single_process_files(tmp_path, capsys):
    args = ["render", str(demo_scene_path()), "--path", "orbit:5", "--width", "96", "--height", "64"]
    assert main([*args, "-o", str(tmp_path / "one")]) == 0
    assert main([*args, "-o", str(tmp_path / "two"), "--workers", "2"]) == 0
    assert "wrote 5 frames" in capsys.readouterr().out
    assert sorted(p.name for p in (tmp_path / "two").iterdir()) == [f"{k:05d}.png" for k in range(5)]
    for k in range(5):
        np.testing.assert_array_equal(read_image(tmp_path / "one" / f"{k:05d}.png"),
                                      read_image(tmp_path / "two" / f"{k:05d}.png"))
    (tmp_path / "two" / "00003.png").unlink()
    assert main([*args, "-o", str(tmp_path / "two"), "--workers", "2", "--resume"]) == 0
    assert "wrote 1 frames" in capsys.readouterr().out
    # a selection's frames carry the cameras' own numbers, in every worker
    assert main([*args, "-o", str(tmp_path / "sel"), "--workers", "2", "--select", "1:5:2"]) == 0
    assert sorted(p.name for p in (tmp_path / "sel").iterdir()) == ["00001.png", "00003.png"]
    for k in (1, 3):
        np.testing.assert_array_equal(read_image(tmp_path / "one" / f"{k:05d}.png"),
                                      read_image(tmp_path / "sel" / f"{k:05d}.png"))


ARGS = ["render", "--path", "orbit:6", "--width", "96", "--height", "64"]


def _video(path: Path) -> list[np.ndarray]:
    from splatgl.imagefiles.video import read_video_frames

    return read_video_frames(path)


@pytest.fixture(scope="module")
def one_process_video(tmp_path_factory):
    pytest.importorskip("av", reason="PyAV is not installed (pip install 'splatgl[video]')")
    out = tmp_path_factory.mktemp("one") / "one.mp4"
    assert main([*ARGS, "-o", str(out)]) == 0
    return out


def test_two_workers_video_equals_the_single_process_video(one_process_video, tmp_path, capsys):
    """Workers write PNG frames quantised as the video writer quantises, so the encoder sees the
    same pixels, and the encoder gives the same stream for the same pixels on one machine (see
    tests/imagefiles/test_video.py for why that needed x264 kept off AVX-512): the decoded frames are equal."""
    out = tmp_path / "two.mp4"
    capsys.readouterr()
    assert main([*ARGS, "-o", str(out), "--workers", "2"]) == 0
    text = capsys.readouterr().out
    one, two = _video(one_process_video), _video(out)
    assert len(two) == 6 and all(np.array_equal(a, b) for a, b in zip(one, two))
    assert os.listdir(tmp_path) == ["two.mp4"]          # the frame folder is gone
    workers, total = summary_counts(text, "frames")
    # two chunks of 3 on one shared queue: each worker usually takes one, but a worker slow to
    # start can find both taken (the summary then lists one worker with 6)
    assert 1 <= len(workers) <= 2 and sum(workers) == total == 6 and all(w % 3 == 0 for w in workers)


def test_failed_assembly_keeps_frames_and_resume_finishes(one_process_video, tmp_path, capsys, monkeypatch):
    """No video (not even a partial one) when assembling fails; the frames stay, and --resume
    renders only the missing ones before encoding."""
    from splatgl.tasks import render_tasks as sharded
    from splatgl.errors import SplatglError

    def fail(*args, **kwargs):
        raise SplatglError("disk full")

    out = tmp_path / "v.mp4"
    with monkeypatch.context() as m:
        m.setattr(sharded, "assemble_video", fail)
        assert main([*ARGS, "-o", str(out), "--workers", "2"]) == 2
    assert "disk full" in capsys.readouterr().err
    frames = frame_folder(out)
    assert os.listdir(tmp_path) == [frames.name] and len(os.listdir(frames)) == 6
    for k in (1, 4):
        (frames / f"{k:05d}.png").unlink()
    assert main([*ARGS, "-o", str(out), "--workers", "2", "--resume"]) == 0
    assert "wrote 2 frames" in capsys.readouterr().out
    assert all(np.array_equal(a, b) for a, b in zip(_video(one_process_video), _video(out)))
    assert os.listdir(tmp_path) == ["v.mp4"]


def test_one_process_video_cannot_resume(tmp_path, capsys):
    assert main([*ARGS, "-o", str(tmp_path / "v.mp4"), "--resume"]) == 2
    assert "cannot be resumed; render it with --workers N or --executor ray" in capsys.readouterr().err


def test_dead_worker_names_its_frames(tmp_path, capsys, monkeypatch):
    """A worker killed mid-chunk stops the run with a one-line error naming the chunk; the
    frames that exist are whole, and --resume finishes the path."""
    monkeypatch.setenv(KILL_ONCE_ENV, str(tmp_path / "killed"))
    assert main([*ARGS, "-o", str(tmp_path / "f"), "--workers", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and " died on frames " in err and "re-run with --resume" in err, err
    assert (tmp_path / "killed").is_file() and len(os.listdir(tmp_path / "f")) < 6
    assert main([*ARGS, "-o", str(tmp_path / "f"), "--workers", "2", "--resume"]) == 0
    assert sorted(os.listdir(tmp_path / "f")) == [f"{k:05d}.png" for k in range(6)]


def test_a_failed_sharded_video_names_the_frames_it_kept(tmp_path, capsys, monkeypatch):
    """A sharded video that stops on an error after its workers rendered (here: encoding it
    fails) says, besides the error, where the frames wait for --resume, as a Ctrl-C does."""
    pytest.importorskip("av", reason="PyAV is not installed (pip install 'splatgl[video]')")
    from splatgl.errors import SplatglError
    from splatgl.tasks import render_tasks

    def full_disk(*args, **kwargs):
        raise SplatglError("v.mp4: cannot write (No space left on device)")

    monkeypatch.setattr(render_tasks, "assemble_video", full_disk)
    out = tmp_path / "v.mp4"
    assert main([*ARGS, "-o", str(out), "--workers", "2"]) == 2
    err = capsys.readouterr().err
    frames = frame_folder(out)
    assert err == ("splatgl: error: v.mp4: cannot write (No space left on device); 6 frames kept "
                   f"in the hidden folder {frames}/ (no video written): re-run with --resume and "
                   "workers (--workers N or --executor ray) to render the rest and write "
                   f"{out}, or delete the folder\n"), err
    monkeypatch.undo()
    assert main([*ARGS, "-o", str(out), "--workers", "2", "--resume"]) == 0
    assert len(_video(out)) == 6 and os.listdir(tmp_path) == ["v.mp4"]


def test_sigterm_mid_video_leaves_no_video_and_resume_encodes(tmp_path):
    """SIGTERM while the workers render: exit 143, no video (nor a partial one), the finished
    frames kept whole for --resume, no worker left running."""
    pytest.importorskip("av", reason="PyAV is not installed (pip install 'splatgl[video]')")
    out = tmp_path / "v.mp4"
    # Each worker writes the first frame of its chunk (0-99, 100-199), then holds until the
    # signal (helpers.start_gated).
    proc = start_gated([*ARGS[:2], "orbit:200", *ARGS[3:], "-o", str(out), "--workers", "2"],
                       frames=1, processes=2)
    frames = frame_folder(out)
    _, err = signal_and_wait(proc, signal.SIGTERM)
    # one line, which names the hidden folder the workers' frames wait in
    assert proc.returncode == 143 and err.splitlines()[-1] == (
        f"splatgl: terminated: 2 frames kept in the hidden folder {frames}/ (no video written): "
        "re-run with --resume and workers (--workers N or --executor ray) to render the rest and "
        f"write {out}, or delete the folder"), err
    assert os.listdir(tmp_path) == [frames.name]
    assert sorted(p.name for p in frames.iterdir()) == ["00000.png", "00100.png"]  # no partials
    assert main([*ARGS[:2], "orbit:200", *ARGS[3:], "-o", str(out), "--workers", "2", "--resume"]) == 0
    assert len(_video(out)) == 200 and os.listdir(tmp_path) == ["v.mp4"]


class _Overflowing:
    """A task whose work leaks a NumPy warning (a float32 overflow)."""

    units = 1

    def run(self, files, report):
        np.array([1e39]).astype(np.float32)
        return None


def test_a_workers_warning_reaches_the_parent_not_the_terminal(monkeypatch, capsys):
    """Issue 38: no raw NumPy warning reaches the user, from a worker process either: its
    warnings go to the parent, which shows them through the command line's one-line policy."""
    import queue
    import warnings

    from splatgl.tasks.local import _worker, reissue_warning

    monkeypatch.setattr(warnings, "showwarning", warnings.showwarning)  # _worker replaces it
    todo, messages = queue.Queue(), queue.Queue()
    for item in ((0, _Overflowing()), None):
        todo.put(item)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        _worker(todo, messages)
    got = [messages.get_nowait() for _ in range(messages.qsize())]
    assert [kind for kind, _, _ in got] == ["start", "warning", "done"]
    _, index, (text, category, filename, lineno) = got[1]
    assert (index, text, category) == (0, "overflow encountered in cast", RuntimeWarning)
    assert filename == __file__ and capsys.readouterr().err == ""
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        reissue_warning(got[1][2])
    assert [(str(w.message), w.category, w.filename) for w in shown] == [
        ("overflow encountered in cast", RuntimeWarning, __file__)]
