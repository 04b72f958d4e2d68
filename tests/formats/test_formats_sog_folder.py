"""A SOG folder (meta.json and its textures) written over an older one is replaced as a whole:
at every instant of the write, and after a write cut off at any step, meta.json loads as the
old scene or the new one, bit-identical, and nothing of the old scene lingers afterwards
(issue 38, item 3: SIGTERM 0.6 s into the write left new textures beside the old meta.json)."""

from __future__ import annotations

import os
import pathlib
import shutil

import numpy as np
import pytest

from splatgl.formats import load_scene, save_scene

from helpers import random_scene

FIELDS = ("means", "quats", "log_scales", "opacity_logits", "sh")


def _files(folder: pathlib.Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def _same(a, b) -> bool:
    return a.sh.shape == b.sh.shape and all(np.array_equal(getattr(a, f), getattr(b, f))
                                            for f in FIELDS)


def _which(folder: pathlib.Path, old, new) -> str:
    """'old' or 'new': what meta.json in ``folder`` loads as (anything else fails the test)."""
    got = load_scene(folder / "meta.json")
    if _same(got, old):
        return "old"
    assert _same(got, new), "meta.json loads as neither the old nor the new scene"
    return "new"


@pytest.fixture
def scenes(tmp_path):
    """An old SOG folder (SH degree 1: six textures) and the new scene (degree 0: five)."""
    folder = tmp_path / "sg"
    folder.mkdir()
    save_scene(folder / "meta.json", random_scene(300, seed=1, degree=1))
    (folder / "notes.txt").write_text("the user's own file")
    old_files = _files(folder)
    new = random_scene(200, seed=2)
    save_scene(tmp_path / "new.meta.json", new)  # what the new scene loads as
    return folder, old_files, load_scene(folder / "meta.json"), new, \
        load_scene(tmp_path / "new.meta.json")


class _Steps:
    """Counts the writes and renames of a write (and can fail the ``fail_at``-th one), or copies
    the folder after each file operation, as a kill at that instant would leave it."""

    def __init__(self, monkeypatch, folder, fail_at=None, snapshots=None):
        self.count, self.fail_at, self.folder, self.snapshots = 0, fail_at, folder, snapshots
        for owner, name in ((os, "replace"), (pathlib.Path, "write_bytes"),
                            (pathlib.Path, "unlink")):
            monkeypatch.setattr(owner, name, self._wrap(getattr(owner, name)))

    def _wrap(self, real):
        def step(*args, **kwargs):
            self.count += real.__name__ != "unlink"  # a cleanup cut short only leaves litter
            if self.count == self.fail_at and real.__name__ != "unlink":
                raise KeyboardInterrupt  # Ctrl-C, or SIGTERM through the CLI
            value = real(*args, **kwargs)
            if self.snapshots is not None:
                self.snapshots.append(_files(self.folder))
            return value
        return step


def test_a_kill_at_any_instant_leaves_the_old_or_the_new_scene(tmp_path, scenes, monkeypatch):
    folder, old_files, old, written, new = scenes
    snapshots = [old_files]
    with monkeypatch.context() as patch:
        _Steps(patch, folder, snapshots=snapshots)
        save_scene(folder / "meta.json", written)
    seen = []
    for i, files in enumerate(snapshots):
        copy = tmp_path / f"at{i}"
        copy.mkdir()
        for name, data in files.items():
            (copy / name).write_bytes(data)
        seen.append(_which(copy, old, new))
    assert seen[0] == "old" and seen[-1] == "new" and len(snapshots) > 10
    assert seen == sorted(seen, key=["old", "new"].index), seen  # one switch, never back
    assert _which(folder, old, new) == "new"
    # nothing of the old scene lingers: its SH palette is gone, no temporary is left
    assert sorted(_files(folder)) == ["means_l.webp", "means_u.webp", "meta.json", "notes.txt",
                                      "quats.webp", "scales.webp", "sh0.webp"]


def _restore(folder: pathlib.Path, files: dict[str, bytes]) -> None:
    shutil.rmtree(folder)
    folder.mkdir()
    for name, data in files.items():
        (folder / name).write_bytes(data)


def test_a_write_cut_off_at_any_step_leaves_a_whole_scene(scenes, monkeypatch):
    """An exception (Ctrl-C; SIGTERM through the CLI) at each file operation in turn: the old
    scene untouched and nothing beside it, or the new scene whole."""
    folder, old_files, old, written, new = scenes
    with monkeypatch.context() as patch:
        steps = _Steps(patch, folder)
        save_scene(folder / "meta.json", written)
    total = steps.count
    assert total > 10
    seen = []
    for step in range(1, total + 1):
        _restore(folder, old_files)
        with monkeypatch.context() as patch, pytest.raises(KeyboardInterrupt):
            _Steps(patch, folder, fail_at=step)
            save_scene(folder / "meta.json", written)
        seen.append(_which(folder, old, new))
        files = _files(folder)
        if seen[-1] == "old":
            assert files == old_files, step
        hidden = [n for n in files if n.startswith(".")]  # only what meta.json names
        assert all(n.encode() in files["meta.json"] for n in hidden), (step, hidden)
    assert "old" in seen and "new" in seen
