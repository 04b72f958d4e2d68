"""On-screen text: the status panel and the key list, rasterised by OpenImageIO.

Text is drawn with ``ImageBufAlgo.render_text`` (its built-in font, as :mod:`splatgl.output.pictures`
labels are) into a small straight-alpha RGBA image on a translucent dark panel; the viewer
uploads it as a texture and alpha-blends it over the top-left corner.  Rasterising costs a few
milliseconds, so :class:`Overlay` redoes it at most :data:`REFRESH_HZ` times a second.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import OpenImageIO as oiio

#: Most status re-rasterisations per second.
REFRESH_HZ = 4.0
FONT_SIZE = 14
LINE_HEIGHT = 17
PADDING = 6
PANEL_ALPHA = 0.6

#: The key list, printed at start and shown with H.
KEYS = (
    ("left drag", "orbit around the target"),
    ("Ctrl+click", "list the pixel's splats front to back (printed; splatgl pixel)"),
    ("right/middle drag", "pan"),
    ("wheel", "zoom (distance)"),
    ("W A S D / arrows", "fly forward, left, back, right"),
    ("Q / E", "fly down / up (hold Shift: 4x faster)"),
    ("Z / X", "roll left / right"),
    ("[ ] or - +", "narrower / wider field of view"),
    ("R", "reset to the start view"),
    ("N / Shift+N, PgDn / PgUp", "next / previous training camera"),
    ("T", "toggle renderer quad / tile"),
    ("0 1 2 3", "cap the SH degree"),
    ("P", "cycle blend precision rgba32f / rgba16f / rgba8"),
    ("Ctrl+D (or Tab)", "depth view (Tab cycles colour / depth / difference)"),
    ("C", "difference view: |quad - tile| heat map"),
    ("F12 or Ctrl+S", "screenshot: PNG as `splatgl render` writes it + camera JSON"),
    ("I", "show / hide the status panel"),
    ("H", "show / hide this key list (also printed)"),
    ("Esc", "quit"),
)


def key_help(separator: str | None = None) -> str:
    """The key list as text, one key per line; columns padded with spaces, or split by
    ``separator`` (the overlay uses a tab to align its proportional font)."""
    width = max(len(k) for k, _ in KEYS)
    if separator is not None:
        return "\n".join(f"{k}{separator}{v}" for k, v in KEYS)
    return "\n".join(f"  {k:<{width}}  {v}" for k, v in KEYS)


def _text_width(text: str, size: int) -> int:
    roi = oiio.ImageBufAlgo.text_size(text or " ", size)
    return roi.width if roi.defined else len(text) * size // 2


def text_image(lines: list[str], size: int = FONT_SIZE) -> np.ndarray:
    """(H, W, 4) float32 straight-alpha image of ``lines`` in white on a translucent panel.

    A tab splits a line into two columns; second columns start at one common x.
    """
    lines = lines or [""]
    cells = [line.split("\t", 1) for line in lines]
    col2 = max((_text_width(c[0], size) + 3 * PADDING for c in cells if len(c) == 2), default=0)
    w = max(_text_width(c[0], size) if len(c) == 1 else col2 + _text_width(c[1], size)
            for c in cells) + 2 * PADDING
    h = LINE_HEIGHT * len(lines) + 2 * PADDING
    buf = oiio.ImageBuf(oiio.ImageSpec(w, h, 4, oiio.FLOAT))
    oiio.ImageBufAlgo.fill(buf, (0.0, 0.0, 0.0, PANEL_ALPHA))
    for i, cell in enumerate(cells):
        y = PADDING + LINE_HEIGHT * i + size - 2  # render_text's y is the baseline
        for x, text in zip((PADDING, PADDING + col2), cell):
            if text.strip():
                oiio.ImageBufAlgo.render_text(buf, x, y, text, size, "", (1.0, 1.0, 1.0, 1.0))
    return np.asarray(buf.get_pixels(oiio.FLOAT), np.float32).reshape(h, w, 4)


@dataclass(frozen=True)
class Status:
    """What the status panel reports about the last frame.

    Times are seconds: ``frame`` the whole frame (render and present), ``sort`` cull + sort
    (quad) or key sort (tile), ``draw`` the GPU drawing (quad: upload + draw; tile: rasterize).
    """

    renderer: str
    fps: float
    frame: float
    sort: float
    draw: float
    splats: str
    settings: str
    size: tuple[int, int]
    fov: float
    view: str
    camera: str
    message: str = ""
    quality: str = ""


def status_lines(s: Status) -> list[str]:
    """The status panel's lines."""
    lines = [
        f"{s.renderer}  {s.fps:5.1f} fps  frame {s.frame * 1e3:6.1f} ms  "
        f"(sort {s.sort * 1e3:.1f}, draw {s.draw * 1e3:.1f})",
        f"splats {s.splats}",
        f"{s.settings}",
    ]
    if s.quality:
        lines.append(s.quality)
    lines += [
        f"{s.size[0]}x{s.size[1]}  fov {s.fov:.1f}  view {s.view}  {s.camera}",
    ]
    if s.message:
        lines.append(s.message)
    lines.append("H: keys")
    return lines


class Overlay:
    """The status panel (and the key list when shown), rate-limited re-rasterisation."""

    def __init__(self, refresh_hz: float = REFRESH_HZ):
        self.interval = 1.0 / refresh_hz
        self.visible = True
        self.show_keys = False
        self.image: np.ndarray | None = None
        self._lines: list[str] | None = None
        self._last = -float("inf")

    def update(self, lines: list[str], now: float, force: bool = False) -> bool:
        """Re-rasterise when the text changed and the last one is old enough (or ``force``);
        returns whether :attr:`image` changed."""
        if self.show_keys:
            lines = lines + ["", "keys:"] + key_help("\t").splitlines()
        if lines == self._lines or (not force and now - self._last < self.interval):
            return False
        self._lines, self._last = lines, now
        self.image = text_image(lines)
        return True
