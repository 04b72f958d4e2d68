"""Evaluate a scene against a dataset's photographs: PSNR and SSIM per view and their means.

Conventions (those of the 3DGS ``render.py`` + ``metrics.py`` workflow):

- the render is clamped to [0, 1]; the photograph is read as float in [0, 1];
- an RGBA photograph is composited over the render's background, ``rgb a + bg (1 - a)``;
- a photograph whose size differs from the camera's is resized to it (OpenImageIO's default
  filter), as 3DGS resizes photographs wider than 1600 px;
- PSNR: ``10 log10(1 / MSE)`` over all pixels and the three channels, per view; the mean is the
  mean of the per-view values;
- SSIM: Wang et al. 2004, an 11x11 Gaussian window with sigma 1.5, C1 = 0.01^2, C2 = 0.03^2,
  population (not sample) covariances, averaged over the "valid" pixels (no padding) and over
  the channels (:func:`splatgl.measure.evaluation.metrics.ssim`).  This equals scikit-image's
  ``structural_similarity(gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
  data_range=1)``.  3DGS's own ``ssim`` zero-pads the borders instead, which reads slightly
  lower on the same images.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Iterator, Optional, Sequence

import numpy as np

from ...datasets.named_camera import NamedCamera
from ...errors import SplatglError
from ...imagefiles.frame_targets import FrameTarget
from ...imagefiles.images import read_image
from ...imagefiles.layer_files import write_layers
from ...output.layers import RenderOutput
from .metrics import check_ssim_size, psnr, ssim
from ...api import Renderer
from ...scene.splats import Scene
from ...scene.settings import RenderSettings, RendererKind
from ...renderers.registry import DEFAULT_RENDERER


@dataclass(frozen=True)
class ViewScore:
    name: str
    psnr: float
    ssim: float


@dataclass(frozen=True)
class Evaluation:
    """Per-view scores (in dataset order) and their means."""

    scores: tuple[ViewScore, ...]

    @property
    def mean_psnr(self) -> float:
        return float(np.mean([s.psnr for s in self.scores]))

    @property
    def mean_ssim(self) -> float:
        return float(np.mean([s.ssim for s in self.scores]))

    def worst(self, count: int) -> list[ViewScore]:
        return sorted(self.scores, key=lambda s: s.psnr)[:count]

    def table(self) -> str:
        mean = f"mean ({len(self.scores)} views)"
        width = max([len("view"), len(mean)] + [len(s.name) for s in self.scores])
        lines = [f"{'view':<{width}}  {'PSNR dB':>8}  {'SSIM':>6}"]
        lines += [f"{s.name:<{width}}  {s.psnr:8.3f}  {s.ssim:6.4f}" for s in self.scores]
        lines.append(f"{mean:<{width}}  {self.mean_psnr:8.3f}  {self.mean_ssim:6.4f}")
        return "\n".join(lines)

    def csv(self) -> str:
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["view", "psnr", "ssim"])
        for s in self.scores:
            w.writerow([s.name, repr(s.psnr), repr(s.ssim)])
        w.writerow(["mean", repr(self.mean_psnr), repr(self.mean_ssim)])
        return buf.getvalue()

    def json(self) -> str:
        def clean(v):
            return None if isinstance(v, float) and math.isinf(v) else v
        obj = {"views": [{k: clean(v) for k, v in asdict(s).items()} for s in self.scores],
               "mean": {"psnr": clean(self.mean_psnr), "ssim": self.mean_ssim, "views": len(self.scores)},
               "ssim_definition": "Wang et al. 2004, 11x11 Gaussian window sigma 1.5, valid region, "
                                  "mean over RGB (= scikit-image gaussian_weights=True, "
                                  "use_sample_covariance=False, data_range=1)"}
        return json.dumps(obj, indent=2) + "\n"


def load_photo(path: Path, width: int, height: int, background: Sequence[float]) -> np.ndarray:
    """(H, W, 3) float32 photograph at the camera's size, RGBA composited over ``background``."""
    img = read_image(path)
    if img.ndim == 2:
        img = img[..., None]
    if img.shape[-1] in (1, 2):  # grey (+ alpha)
        img = np.concatenate([np.repeat(img[..., :1], 3, -1), img[..., 1:]], -1)
    if img.shape[:2] != (height, width):
        img = _resize(img, width, height)
    rgb = img[..., :3]
    if img.shape[-1] >= 4:
        a = img[..., 3:4]
        rgb = rgb * a + np.asarray(background, np.float32) * (1.0 - a)
    return np.ascontiguousarray(rgb, np.float32)


def _resize(img: np.ndarray, width: int, height: int) -> np.ndarray:
    import OpenImageIO as oiio

    h, w, c = img.shape
    src = oiio.ImageBuf(oiio.ImageSpec(w, h, c, oiio.FLOAT))
    src.set_pixels(oiio.ROI(0, w, 0, h, 0, 1, 0, c), np.ascontiguousarray(img, np.float32))
    dst = oiio.ImageBufAlgo.resize(src, roi=oiio.ROI(0, width, 0, height, 0, 1, 0, c))
    return np.asarray(dst.get_pixels(oiio.FLOAT), np.float32).reshape(height, width, c)


@dataclass(frozen=True)
class Pair:
    """One evaluated view: its score, the clamped render and the photograph, (H, W, 3)."""

    score: ViewScore
    render: np.ndarray
    photo: np.ndarray


@dataclass(frozen=True)
class RenderFiles:
    """Where ``eval --renders`` writes each view's render: ``folder/<photograph stem><suffix>``
    with the layers ``frames`` names (a :class:`~splatgl.imagefiles.frame_targets.FrameTarget` of the
    folder: its format, ``--layers`` and normal space)."""

    folder: Path
    frames: FrameTarget

    def path(self, view: NamedCamera) -> Path:
        return self.folder / (Path(view.name).stem + Path(self.frames.pattern).suffix)

    def check(self, views: Sequence[NamedCamera]) -> None:
        """Refuse two views that would write one file (before any work)."""
        seen: dict[Path, str] = {}
        for view in views:
            path = self.path(view)
            if path in seen:
                raise SplatglError(f"--renders {self.folder}: views {seen[path]!r} and {view.name!r} "
                                   f"would both write {path.name}")
            seen[path] = view.name

    def write(self, view: NamedCamera, out: RenderOutput) -> None:
        write_layers(self.path(view), out, self.frames.files(view.camera))


def evaluate_views(renderer: Renderer, scene: Scene, views: Sequence[NamedCamera],
                   settings: RenderSettings = RenderSettings(),
                   kind: RendererKind = DEFAULT_RENDERER,
                   renders: RenderFiles | None = None) -> Iterator[Pair]:
    """Render each view and score it against its photograph, yielding as it goes (and with
    ``renders``, write each view's layers)."""
    for view in views:
        if view.image is None:
            raise SplatglError(f"view {view.name!r} has no photograph to compare with")
        check_ssim_size(view.camera.width, view.camera.height, f"{view.image}: evaluated at")
    if renders is not None:
        renders.check(views)
        renders.frames.prepare()
    layers = renders.frames.layers if renders is not None else None
    outs = renderer.render_many(scene, [v.camera for v in views], settings, kind,
                                layers=layers)
    for view, out in zip(views, outs):
        if renders is not None:
            renders.write(view, out if layers is not None else RenderOutput(out, None))
        rgba = out.rgba if layers is not None else out
        got = np.clip(rgba[..., :3], 0.0, 1.0)
        photo = load_photo(view.image, view.camera.width, view.camera.height, settings.background)
        yield Pair(ViewScore(view.name, psnr(got, photo), ssim(got, photo)), got, photo)


def evaluate(renderer: Renderer, scene: Scene, views: Sequence[NamedCamera],
             settings: RenderSettings = RenderSettings(), kind: RendererKind = DEFAULT_RENDERER,
             keep_worst: int = 0,
             progress: Optional[Callable[[int, int, str], None]] = None,
             renders: RenderFiles | None = None) -> tuple[Evaluation, list[Pair]]:
    """Score every view; also return the ``keep_worst`` lowest-PSNR pairs (for a sheet); with
    ``renders``, write each view's render and layers (:class:`RenderFiles`)."""
    scores, kept = [], []
    for n, pair in enumerate(evaluate_views(renderer, scene, views, settings, kind, renders), 1):
        scores.append(pair.score)
        if keep_worst:
            kept = sorted(kept + [pair], key=lambda p: p.score.psnr)[:keep_worst]
        if progress is not None:
            progress(n, len(views), "evaluating views")
    return Evaluation(tuple(scores)), kept


def worst_sheet(pairs: Sequence[Pair]) -> np.ndarray:
    """(H, W, 4) picture: per pair one row of render | photograph | error heat map, labelled."""
    from ...imagefiles.pictures import heatmap, side_by_side

    rows = []
    for p in pairs:
        name = f"{p.score.name}: {p.score.psnr:.2f} dB, SSIM {p.score.ssim:.3f}"
        pair = side_by_side(p.render, p.photo, (f"render  {name}", "photograph"))
        heat = heatmap(p.render, p.photo, 0.25)[: p.render.shape[0]]
        gap = np.full((pair.shape[0], 4, 4), 0.5, np.float32)
        rows.append(np.concatenate([pair, gap, heat], axis=1))
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 4), (0, width - r.shape[1]), (0, 0)), constant_values=0.5) for r in rows]
    return np.concatenate(rows, axis=0)
