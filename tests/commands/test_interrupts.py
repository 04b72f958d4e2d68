"""Ctrl-C, SIGTERM and a closed stdout: one line (or none), the right exit code, no file left;
and the progress reports that long renders give between their bounded pieces of work."""

from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
import textwrap

import numpy as np

from splatgl.progress import StderrProgress, format_seconds

from helpers import signal_and_wait

DEMO_ARGS = ["--width", "48", "--height", "32"]


def run_python(code: str, *args: str, **popen) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", textwrap.dedent(code), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen)


def test_sigterm_during_convert_removes_the_partial_file(tmp_path, shared_scenes):
    """The writer announces itself and then waits for ever, so the signal lands mid-write and
    only the signal can end the command."""
    out = tmp_path / "out.ply"
    proc = run_python("""
        import sys, threading
        from splatgl.formats import ply_write
        real = ply_write.write
        def stuck_write(path, scene):
            real(path, scene)           # the temporary now exists, complete or not
            print("writing", flush=True)
            threading.Event().wait()    # until SIGTERM raises here
            print("not interrupted", flush=True)
        ply_write.write = stuck_write
        from splatgl.cli import main
        sys.exit(main(["convert", sys.argv[1], sys.argv[2]]))
        """, str(shared_scenes / "fixtures" / "minimal.splat"), str(out), start_new_session=True)
    assert proc.stdout.readline() == "writing\n"
    assert [p.name for p in tmp_path.iterdir()] == [f".out.partial{proc.pid}.ply"]  # temp_path
    rest, err = signal_and_wait(proc, signal.SIGTERM)
    assert (proc.returncode, rest, err) == (143, "", "splatgl: terminated\n")
    assert list(tmp_path.iterdir()) == []


def test_interrupt_during_start_up_imports_is_one_line():
    """SIGINT delivered while numpy is being imported (the bulk of the start-up)."""
    proc = run_python("""
        import os, signal, sys
        class Interrupter:
            def find_spec(self, name, path=None, target=None):
                if name == "numpy":
                    sys.meta_path.remove(self)
                    os.kill(os.getpid(), signal.SIGINT)
                return None
        from splatgl.cli import main      # the standard library only: numpy not loaded yet
        assert "numpy" not in sys.modules
        sys.meta_path.insert(0, Interrupter())
        sys.exit(main(["info", "whatever.ply"]))
        """)
    out, err = proc.communicate(timeout=60)
    assert (proc.returncode, out, err) == (130, "", "splatgl: interrupted\n")


def test_closed_stdout_is_quiet(shared_scenes):
    proc = subprocess.Popen([sys.executable, "-m", "splatgl", "info",
                             str(shared_scenes / "ply" / "donut_sh0.ply")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # like `| head -0`: every write fails with EPIPE
    err = proc.stderr.read().decode()
    proc.wait(timeout=60)
    assert (proc.returncode, err) == (141, "")


# ------------------------------------------------------------------------------ progress
def test_meter_estimates_the_time_left():
    clock = iter([0.0, 10.0, 30.0, 40.0]).__next__
    stream = io.StringIO()
    meter = StderrProgress(stream=stream, clock=clock)
    for done in (0, 25, 75, 100):
        meter(done, 100, "reference: rasterizing tiles")
    assert stream.getvalue().splitlines() == [
        "reference: rasterizing tiles:   0.0% (0 / 100)",
        "reference: rasterizing tiles:  25.0% (25 / 100), about 30 s left",
        "reference: rasterizing tiles:  75.0% (75 / 100), about 10 s left",
        "reference: rasterizing tiles: 100.0% (100 / 100)",
    ]
    assert [format_seconds(s) for s in (0.2, 59.4, 125, 3725)] == ["1 s", "59 s", "2 min 05 s",
                                                                    "1 h 02 min"]


def test_reference_reports_every_batch_and_the_image_does_not_change():
    from splatgl import default_camera
    from splatgl.commands._common import demo_scene_path
    from splatgl.formats import load_scene
    from splatgl.reference.binning import emit_keys, sort, tile_ranges
    from splatgl.reference.rasterize import rasterize
    from helpers import project
    from splatgl.scene.settings import RenderSettings

    scene = load_scene(demo_scene_path())
    proj = project(scene, default_camera(scene, 96, 64), RenderSettings(), np.float32)
    keys, values = sort(*emit_keys(proj))
    ranges = tile_ranges(keys, proj.n_tiles)
    calls = []
    banded = rasterize(proj, values, ranges, tiles_per_batch=3, workers=2,
                       progress=lambda d, t, w: calls.append((d, t, w)))
    whole = rasterize(proj, values, ranges, tiles_per_batch=10_000, workers=1)
    busy = int((ranges[:, 1] > ranges[:, 0]).sum())
    assert len(calls) == -(-busy // 3)
    assert [d for d, _, _ in calls] == sorted(d for d, _, _ in calls)
    assert calls[-1] == (busy, busy, "reference: rasterizing tiles")
    np.testing.assert_array_equal(banded.transmittance, whole.transmittance)
    np.testing.assert_allclose(banded.color, whole.color, rtol=0, atol=1e-6)


def test_tile_renderer_draws_in_bands_and_reports_them(gl_renderer, monkeypatch):
    from splatgl import default_camera
    from splatgl.renderers import tile
    from splatgl.commands._common import demo_scene_path
    from splatgl.formats import load_scene
    from splatgl.scene.settings import RendererKind, RenderSettings

    scene = load_scene(demo_scene_path())
    camera = default_camera(scene, 320, 240)  # 20 x 15 tiles
    calls = []
    monkeypatch.setattr(tile, "RASTER_BAND_TILES", 60)  # 3 tile rows a band: 5 bands
    banded = gl_renderer.render(scene, camera, RenderSettings(), RendererKind.TILE,
                                progress=lambda d, t, w: calls.append((d, t)))
    assert calls == [(60, 300), (120, 300), (180, 300), (240, 300), (300, 300)]
    monkeypatch.setattr(tile, "RASTER_BAND_TILES", 10_000)
    whole = gl_renderer.render(scene, camera, RenderSettings(), RendererKind.TILE)
    np.testing.assert_array_equal(banded, whole)  # same pixels: bands only split the dispatch


def test_cli_progress_lines_for_a_reference_render(tmp_path):
    env = dict(os.environ, SPLATGL_PROGRESS="1")
    proc = subprocess.run([sys.executable, "-m", "splatgl", "render", "--renderer", "reference",
                           "-o", str(tmp_path / "r.png"), *DEMO_ARGS], capture_output=True,
                          text=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "reference: rasterizing tiles: 100.0%" in proc.stderr


def test_ctrl_c_during_converts_report_says_the_output_is_whole(tmp_path, capsys, monkeypatch):
    """A Ctrl-C while convert measured its round trip said only 'interrupted', yet OUT was
    complete (and a second run refused it as existing): the line now says so."""
    from splatgl.cli import main
    from splatgl.commands._common import demo_scene_path
    from splatgl.formats import convert as convert_module, load_scene

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(convert_module, "conversion_error", stopped)
    out = tmp_path / "out.spz"
    assert main(["convert", str(demo_scene_path()), str(out)]) == 130
    assert capsys.readouterr().err == (
        f"splatgl: interrupted: {out} was written whole; only its round-trip report was cut short "
        "(read it with 'splatgl info', or convert again with --force for the report)\n")
    assert load_scene(out).count == load_scene(demo_scene_path()).count
