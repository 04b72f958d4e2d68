"""On-screen text: the status panel and the key list, rasterised by OpenImageIO.

Text is drawn with ``ImageBufAlgo.render_text`` (its built-in font, as :mod:`splatgl.imagefiles.pictures`
labels are) into a small straight-alpha RGBA image on a translucent dark panel; the viewer
uploads it as a texture and alpha-blends it over the top-left corner.  Rasterising costs a few
milliseconds, so :class:`Overlay` redoes it at most :data:`REFRESH_HZ` times a second.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import OpenImageIO as oiio

#: Most status re-rasterisations per second.
REFRESH_HZ = 4.0
FONT_SIZE = 14
LINE_HEIGHT = 17
PADDING = 6
PANEL_ALPHA = 0.6
#: The compact panel of a small window (:data:`COMPACT_WINDOW`): smaller text, fewer lines.
COMPACT_FONT_SIZE = 11
COMPACT_LINE_HEIGHT = 13
#: Windows narrower or lower than this (pixels) get the compact panel.
COMPACT_WINDOW = (960, 540)
#: Seconds a status message ("saved ...", "Tab skipped ...") stays on the panel.
MESSAGE_SECONDS = 4.0
#: Transparent border around each rendered piece of text (pixels), for glyphs that overhang.
CELL_MARGIN = 4

#: The key list, printed at start and shown with H.
KEYS = (
    ("left drag", "orbit around the target"),
    ("Ctrl+click", "list the pixel's splats front to back (printed; splatgl pixel)"),
    ("right/middle drag", "pan"),
    ("wheel", "zoom towards the cursor"),
    ("W A S D / arrows", "fly forward, left, back, right"),
    ("Q / E", "fly down / up (hold Shift: 4x faster)"),
    ("Z / X", "roll left / right"),
    ("[ ] or - +", "narrower / wider field of view"),
    ("R", "reset to the start view"),
    ("N / Shift+N, PgDn / PgUp", "next / previous training camera"),
    ("T", "next renderer: quad / tile / cpu"),
    ("0 1 2 3", "cap the SH degree"),
    ("P", "cycle blend precision rgba32f / rgba16f / rgba8"),
    ("Ctrl+D (or Tab)", "depth view (Tab cycles colour / depth / difference)"),
    ("C", "difference view: |quad - tile| heat map"),
    ("F12 or Ctrl+S", "screenshot: PNG as `splatgl render` writes it + camera JSON"),
    ("U", "cycle the up direction +y / -y / +z / -z"),
    ("B", "cycle the background black / white / grey"),
    ("K", "record the camera's flight / stop: a path file for `splatgl render --path`"),
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


@lru_cache(maxsize=512)
def _text_width(text: str, size: int) -> int:
    roi = oiio.ImageBufAlgo.text_size(text or " ", size)
    return roi.width if roi.defined else len(text) * size // 2


@lru_cache(maxsize=256)
def _cell(text: str, size: int) -> np.ndarray:
    """``text`` rendered white on transparent: (line height + 2 CELL_MARGIN, width + 2
    CELL_MARGIN, 4) float32 coverage in every channel, its baseline at CELL_MARGIN + size - 2
    and its left edge at CELL_MARGIN (the margin keeps overhanging glyphs whole).  Kept per text:
    most of the panel's lines (and all of the key list) repeat from one refresh to the next,
    and each render_text costs about 1.5 ms."""
    w = _text_width(text, size) + 2 * CELL_MARGIN
    h = _line_height(size) + 2 * CELL_MARGIN
    buf = oiio.ImageBuf(oiio.ImageSpec(w, h, 4, oiio.FLOAT))
    oiio.ImageBufAlgo.render_text(buf, CELL_MARGIN, CELL_MARGIN + size - 2, text, size, "",
                                  (1.0, 1.0, 1.0, 1.0))
    cell = np.asarray(buf.get_pixels(oiio.FLOAT), np.float32).reshape(h, w, 4)
    cell.flags.writeable = False
    return cell


def _line_height(size: int) -> int:
    return COMPACT_LINE_HEIGHT if size <= COMPACT_FONT_SIZE else LINE_HEIGHT


def text_image(lines: list[str], size: int = FONT_SIZE) -> np.ndarray:
    """(H, W, 4) float32 straight-alpha image of ``lines`` in white on a translucent panel.

    A tab splits a line into two columns; second columns start at one common x.  Each piece
    of text is rendered once (:func:`_cell`) and laid over the panel as render_text would
    draw it there: ``pixel = coverage * white + (1 - coverage) * pixel``.
    """
    lines = lines or [""]
    cells = [line.split("\t", 1) for line in lines]
    col2 = max((_text_width(c[0], size) + 3 * PADDING for c in cells if len(c) == 2), default=0)
    w = max(_text_width(c[0], size) if len(c) == 1 else col2 + _text_width(c[1], size)
            for c in cells) + 2 * PADDING
    line_height = _line_height(size)
    h = line_height * len(lines) + 2 * PADDING
    image = np.zeros((h, w, 4), np.float32)
    image[..., 3] = PANEL_ALPHA
    for i, cell in enumerate(cells):
        top = PADDING + line_height * i
        for x, text in zip((PADDING, PADDING + col2), cell):
            if text.strip():
                _over(image, _cell(text, size), x - CELL_MARGIN, top - CELL_MARGIN)
    return image


def _over(image: np.ndarray, cell: np.ndarray, x: int, y: int) -> None:
    """Lay ``cell`` (coverage, white) over ``image`` with its top-left corner at (x, y),
    clipped to the image."""
    h, w = image.shape[:2]
    x0, y0 = max(x, 0), max(y, 0)
    x1, y1 = min(x + cell.shape[1], w), min(y + cell.shape[0], h)
    if x0 >= x1 or y0 >= y1:
        return
    cov = cell[y0 - y:y1 - y, x0 - x:x1 - x]
    region = image[y0:y1, x0:x1]
    region *= 1.0 - cov
    region += cov


@dataclass(frozen=True)
class Status:
    """What the status panel reports about the last frames.

    ``fps``: the rate of recent frames (``moving``: of the moving frames alone, the drafts a
    frame budget draws while the camera moves); ``frame``, ``sort`` and ``draw``: seconds of
    the last frame drawn in full (with a budget: the last exact one), ``frame`` the whole of it
    (render and present), ``sort`` cull + sort (quad) or key sort (tile), ``draw`` the rest of
    the render; 0 before there is one.  ``splats`` is a whole phrase ("splats 1,204 visible /
    1,604"); ``fov`` the field of view as text (a lens's own, not the orbit's).
    """

    renderer: str
    fps: float
    frame: float
    sort: float
    draw: float
    splats: str
    settings: str
    size: tuple[int, int]
    fov: str
    view: str
    camera: str
    message: str = ""
    quality: str = ""
    moving: bool = False


def _rate_and_cost(s: Status, compact: bool) -> str:
    rate = f"{s.fps:.1f} fps" if s.fps > 0 else "- fps"
    if s.moving:
        rate = f"moving {rate}"
    label = "exact" if s.moving else "frame"
    if s.frame <= 0:
        return f"{rate}  {label} -"
    cost = f"{label} {s.frame * 1e3:.1f} ms"
    return f"{rate}  {cost}" if compact else \
        f"{rate}  {cost} (sort {s.sort * 1e3:.1f}, draw {s.draw * 1e3:.1f})"


def status_lines(s: Status, compact: bool = False) -> list[str]:
    """The status panel's lines (``compact``: the few that matter, for a small window)."""
    where = f"{s.size[0]}x{s.size[1]}  {s.fov}  view {s.view}  {s.camera}".rstrip()
    if compact:
        lines = [f"{s.renderer}  {_rate_and_cost(s, True)}", where]
        if s.quality:
            lines.append(s.quality)
        return lines + ([s.message] if s.message else [])
    lines = [f"{s.renderer}  {_rate_and_cost(s, False)}", s.splats, s.settings]
    if s.quality:
        lines.append(s.quality)
    lines.append(where)
    if s.message:
        lines.append(s.message)
    lines.append("H: keys")
    return lines


class Message:
    """The viewer's last word for the status line, shown for :data:`MESSAGE_SECONDS`."""

    def __init__(self, seconds: float = MESSAGE_SECONDS):
        self.seconds, self._text, self._at = seconds, "", -float("inf")

    def say(self, text: str, now: float | None = None) -> None:
        self._text, self._at = text, time.monotonic() if now is None else now

    def current(self, now: float | None = None) -> str:
        """The message, or "" once it is older than :attr:`seconds`."""
        now = time.monotonic() if now is None else now
        return self._text if now - self._at < self.seconds else ""


class Overlay:
    """The status panel (and the key list when shown), rate-limited re-rasterisation.

    :attr:`visible` is the user's toggle (I); with the panel hidden the viewer still hands
    over its message alone (a screenshot's confirmation), so :attr:`image` may be set."""

    def __init__(self, refresh_hz: float = REFRESH_HZ):
        self.interval = 1.0 / refresh_hz
        self.visible = True
        self.show_keys = False
        self.image: np.ndarray | None = None
        self.full = True      # whether :attr:`image` is the whole panel (not a message alone)
        self._lines: list[str] | None = None
        self._last = -float("inf")

    @property
    def lines(self) -> list[str]:
        """The lines :attr:`image` shows."""
        return list(self._lines or [])

    def update(self, lines: list[str], now: float, force: bool = False,
               compact: bool = False, full: bool = True) -> bool:
        """Re-rasterise when the text changed and the last one is old enough (or ``force``),
        in the small font where ``compact``; no lines: no image; ``full``: the lines are the
        whole panel (hidden with it), not a message alone.  Returns whether :attr:`image`
        changed."""
        if self.show_keys:
            lines = lines + ["", "keys:"] + key_help("\t").splitlines()
        if lines == self._lines or (not force and now - self._last < self.interval):
            return False
        self._lines, self._last, self.full = lines, now, full
        self.image = text_image(lines, COMPACT_FONT_SIZE if compact else FONT_SIZE) \
            if lines else None
        return True
