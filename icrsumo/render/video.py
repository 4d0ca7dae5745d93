"""Pictures of BEV rasters (:mod:`icrsumo.render`): RGB images and PNG bytes, a map view for the
report, captioned frames, and episode videos with the instruction under the BEV. Text is drawn
with cv2's Hershey fonts: ASCII only, other characters become '?'."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from .bev import CHANNELS, BevRenderer

#: RGB colours of the channels in to_rgb, painted in this order (later on top)
_PALETTE = tuple((CHANNELS.index(name), colour) for name, colour in (
    ("drivable", (96, 96, 96)),
    ("markings", (255, 255, 255)),
    ("stop", (230, 30, 30)),
    ("go", (40, 230, 70)),
    ("vehicles", (40, 90, 255)),
    ("pedestrians", (255, 0, 255)),
    ("ego", (0, 170, 0)),
))
_BACKGROUND = (20, 20, 20)


def to_rgb(raster: np.ndarray) -> np.ndarray:
    """(C, H, W) raster -> (H, W, 3) uint8 RGB image: near-black background, grey road, white
    markings, red/green stop lines, blue vehicles, magenta pedestrians, green ego (on top)."""
    raster = np.asarray(raster)
    if raster.ndim != 3 or raster.shape[0] != len(CHANNELS):
        raise ValueError(f"raster must have shape ({len(CHANNELS)}, H, W), got {raster.shape}")
    img = np.empty((*raster.shape[1:], 3), dtype=np.uint8)
    img[:] = _BACKGROUND
    for ch, colour in _PALETTE:
        img[raster[ch] > 0] = colour
    return img


def _ascii(text: str) -> str:
    """cv2's Hershey fonts draw ASCII only: other characters become '?'."""
    return "".join(ch if 32 <= ord(ch) < 127 else ("?" if not ch.isspace() else " ") for ch in text)


def map_view_png(renderer: BevRenderer, x: float, y: float, yaw: float,
                 size: tuple[float, float] = (4.9, 2.1)) -> bytes:
    """PNG bytes of the BEV's static map layers with the ego at (x, y, yaw) (m, rad) and no
    other actor: what the report shows where the episode log holds the ego's poses only."""
    raster = renderer.render((x, y, yaw), size, None, None, {})
    return png_bytes(to_rgb(raster))


def png_bytes(rgb: np.ndarray) -> bytes:
    """PNG bytes of an (H, W, 3) uint8 RGB image (the same pixels give the same bytes)."""
    ok, buf = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    if not ok:
        raise OSError("cannot encode a PNG")
    return buf.tobytes()


def wrap_text(text: str, max_px: int, max_lines: int, font: int = cv2.FONT_HERSHEY_SIMPLEX,
              fscale: float = 0.45, words: bool = True) -> list[str]:
    """``text`` (ASCII-fied) in lines at most ``max_px`` wide when drawn with ``font`` at
    ``fscale``, broken between words (``words=False``: one line), at most ``max_lines``; what
    does not fit ends in "..."."""
    def fits(t: str) -> bool:
        return cv2.getTextSize(t, font, fscale, 1)[0][0] <= max_px

    def cut(t: str) -> str:  # shorten to one line ending in "..."
        while t and not fits(t + "..."):
            t = t[:-1]
        return t + "..."

    if not words:
        line = _ascii(text)
        return [line if fits(line) else cut(line)]
    lines: list[str] = []
    for word in _ascii(text).split():
        if lines and fits(f"{lines[-1]} {word}"):
            lines[-1] = f"{lines[-1]} {word}"
        else:
            lines.append(word if fits(word) else cut(word))
    if len(lines) > max_lines:
        lines = lines[:max_lines]
        lines[-1] = cut(lines[-1])
    return lines


def write_image(path: Path, bgr: np.ndarray, caption: str = "") -> None:
    """Write a BGR frame (:meth:`VideoWriter.frame`) as an image file (PNG by its suffix), with
    an optional ``caption`` in red on a band below it (wrapped, at most 3 lines)."""
    if caption:
        lines = wrap_text(caption, bgr.shape[1] - 12, 3)
        band = np.zeros((10 + 18 * len(lines), bgr.shape[1], 3), dtype=np.uint8)
        for i, line in enumerate(lines):
            cv2.putText(band, line, (6, 19 + 18 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (60, 60, 255), 1,
                        cv2.LINE_AA)
        bgr = np.vstack([bgr, band])
    if not cv2.imwrite(str(path), bgr):
        raise OSError(f"cannot write the image {path}")


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """File descriptor 2 sent to /dev/null for the duration (what C libraries print there)."""
    with contextlib.suppress(OSError, ValueError, AttributeError):
        sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no fd 2 at all: nothing to quiet
        yield
        return
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


class VideoWriter:
    """BEV video of an episode: each frame is :func:`to_rgb` of a raster scaled ``scale`` x
    (nearest), with the instruction text (and an optional notice) in a band below and the speed
    in the top-left corner. Use as a context manager.

    The container follows ``path``'s suffix: ``.webm`` (the default) is VP8 video, which
    Chromium, Firefox and Safari play in a page or straight from the file; ``.mp4`` is MPEG-4
    Part 2 (mp4v: desktop players, not browsers); ``.avi`` is Motion JPEG. Where this OpenCV
    build cannot write the codec, the next one in that order is written, with its suffix.
    :attr:`path` is the file actually written (known after the first frame). Text is drawn with
    a Hershey font: ASCII only, other characters become '?'.
    """

    #: suffix -> (fourcc, suffix) tried in order: the asked-for container first, then fallbacks
    CODECS = {".webm": (("VP80", ".webm"), ("mp4v", ".mp4"), ("MJPG", ".avi")),
              ".mp4": (("mp4v", ".mp4"), ("MJPG", ".avi")),
              ".avi": (("MJPG", ".avi"),)}

    #: text lines in the band under the BEV (instruction lines + one notice line)
    TEXT_LINES = 4

    def __init__(self, path: Path, fps: float = 10.0, scale: int = 4) -> None:
        if fps <= 0 or scale < 1:
            raise ValueError(f"VideoWriter needs fps > 0 and scale >= 1, got fps={fps} scale={scale}")
        self.path = Path(path)
        self.fps = float(fps)
        self.scale = int(scale)
        self.frames = 0
        self._writer = None
        self._size: tuple[int, int] | None = None  # (raster H, W)
        self._closed = False

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _open(self, h: int, w: int) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        size = (w * self.scale, h * self.scale + self._band_height())
        codecs = self.CODECS.get(self.path.suffix.lower(), self.CODECS[".webm"])
        for fourcc, suffix in codecs:
            target = self.path.with_suffix(suffix)
            with _quiet_stderr():  # OpenCV's FFmpeg prints a harmless tag warning for WebM
                vw = cv2.VideoWriter(str(target), cv2.VideoWriter_fourcc(*fourcc), self.fps, size)
            if vw.isOpened():
                self._writer, self.path = vw, target
                return
            vw.release()
        tried = ", ".join(f for f, _ in codecs)
        raise RuntimeError(f"cannot open a video writer for {self.path} (this OpenCV writes none of {tried})")

    def _band_height(self) -> int:
        return 8 + 18 * self.TEXT_LINES

    def add(self, raster: np.ndarray, text: str, notice: str = "", speed: float | None = None,
            t: float | None = None) -> None:
        """Append one frame: raster (C, H, W) as from :meth:`BevRenderer.render`, the current
        instruction ``text``, an optional ``notice``, the ego ``speed`` (m/s) and the time
        ``t`` (s)."""
        if self._closed:
            raise RuntimeError("VideoWriter is closed")
        h, w = raster.shape[1:]
        if self._size is None:
            self._size = (h, w)
            self._open(h, w)
        elif self._size != (h, w):
            raise ValueError(f"raster size {(h, w)} differs from the first frame's {self._size}")
        self._writer.write(self.frame(raster, text, notice, speed, t))
        self.frames += 1

    def frame(self, raster: np.ndarray, text: str, notice: str = "", speed: float | None = None,
              t: float | None = None) -> np.ndarray:
        """One frame as :meth:`add` writes it: (H * scale + band, W * scale, 3) uint8, BGR."""
        rgb = to_rgb(raster)
        h, w = rgb.shape[:2]
        bev = cv2.resize(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), (w * self.scale, h * self.scale),
                         interpolation=cv2.INTER_NEAREST)
        band = np.zeros((self._band_height(), bev.shape[1], 3), dtype=np.uint8)
        font, fscale = cv2.FONT_HERSHEY_SIMPLEX, 0.45
        max_px = bev.shape[1] - 12

        lines = wrap_text(text, max_px, self.TEXT_LINES - (1 if notice else 0), font, fscale)
        rows = [(ln, (255, 255, 255)) for ln in lines]
        if notice:
            rows.append((wrap_text(" ".join(_ascii(notice).split()), max_px, 1, font, fscale, words=False)[0],
                         (0, 220, 255)))
        for i, (ln, colour) in enumerate(rows):
            cv2.putText(band, ln, (6, 20 + 18 * i), font, fscale, colour, 1, cv2.LINE_AA)
        corner = " ".join(x for x in (f"{t:6.1f} s" if t is not None else "",
                                      f"{speed:5.1f} m/s" if speed is not None else "") if x)
        if corner:
            cv2.putText(bev, corner, (6, 18), font, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
        return np.ascontiguousarray(np.vstack([bev, band]))

    def close(self) -> None:
        """Finish the file (idempotent)."""
        if self._writer is not None:
            self._writer.release()
            self._writer = None
        self._closed = True
