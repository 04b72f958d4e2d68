"""The shared test helpers themselves: the scene factory is seeded and places its layouts where
the tests look, the damaged-file check fails what it must, and a process that outlives its
signal is killed, not left behind."""

from __future__ import annotations

import signal
import subprocess
import sys

import numpy as np
import pytest

from splatgl.errors import SceneFormatError
from splatgl.scene.splats import SplatKind

from helpers import IN_DEPTH, IN_VIEW, SURFELS, check_case, random_scene, signal_and_wait


def test_random_scene_is_seeded():
    a, b, c = random_scene(50, 1, degree=2), random_scene(50, 1, degree=2), random_scene(50, 2, degree=2)
    assert a.means.tobytes() == b.means.tobytes() and a.sh.tobytes() == b.sh.tobytes()
    assert a.means.tobytes() != c.means.tobytes()
    assert a.sh.shape == (50, 9, 3) and np.abs(a.sh[:5, 0]).max() > 2.0  # wild colours first


@pytest.mark.parametrize("layout", [IN_VIEW, IN_DEPTH], ids=["in_view", "in_depth"])
def test_layouts_lie_in_front_of_an_identity_camera(layout):
    scene = random_scene(3000, 0, **layout)
    z = scene.means[:, 2]
    assert z.min() > 0.5 and 2.0 < np.median(z) < 6.0
    assert np.abs(scene.means[:, :2]).max() < 5.0


def test_surfels_layout_gives_two_scales():
    scene = random_scene(10, 0, degree=1, **SURFELS)
    assert scene.kind is SplatKind.SURFEL_2D and scene.log_scales.shape == (10, 2)


def test_check_case_fails_a_load_beyond_its_memory_bound(tmp_path):
    def greedy(path):  # what a reader trusting a damaged header count would do
        np.ones(64 << 20, np.uint8)
        raise SceneFormatError(path, "count too large")

    with pytest.raises(AssertionError, match="peak memory"):
        check_case(greedy, tmp_path / "a.bin", b"0123456789", "greedy")


def test_check_case_fails_other_exceptions_and_silent_loads(tmp_path):
    def crash(path):
        raise IndexError("index 7 is out of bounds")

    def refuse(path):
        raise SceneFormatError(path, "truncated")

    with pytest.raises(pytest.fail.Exception, match="IndexError"):
        check_case(crash, tmp_path / "a.bin", b"x", "crash")
    with pytest.raises(AssertionError, match="loaded without an error"):
        check_case(lambda path: random_scene(1), tmp_path / "a.bin", b"x", "silent", must_fail=True)
    assert check_case(refuse, tmp_path / "a.bin", b"x", "refused", must_fail=True).endswith("truncated")


def test_signal_and_wait_kills_a_process_that_ignores_the_signal():
    proc = subprocess.Popen([sys.executable, "-c", "import signal, sys, threading; "
                             "signal.signal(signal.SIGTERM, signal.SIG_IGN); print('ready'); "
                             "sys.stdout.flush(); threading.Event().wait()"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    assert proc.stdout.readline() == "ready\n"
    with pytest.raises(pytest.fail.Exception, match="still running 1 s after signal 15"):
        signal_and_wait(proc, signal.SIGTERM, hang_guard=1.0)
    assert proc.returncode == -signal.SIGKILL  # killed, not left behind
