"""The BEV raster and its pictures; the only part of the package that uses cv2.

:mod:`icrsumo.render.bev` rasterises a SUMO scene into the ``(C, H, W)`` raster an agent sees
(:class:`BevSpec`, :class:`BevRenderer`, the frame convention); :mod:`icrsumo.render.video`
turns rasters into RGB images, PNG bytes, captioned frames and episode videos. Every public name
of both is importable from here.
"""

from __future__ import annotations

from .bev import CHANNELS, PEDESTRIAN_M, STOP_LINE_M, BevRenderer, BevSpec
from .video import VideoWriter, map_view_png, png_bytes, to_rgb, wrap_text, write_image

__all__ = ["CHANNELS", "PEDESTRIAN_M", "STOP_LINE_M", "BevRenderer", "BevSpec", "VideoWriter",
           "map_view_png", "png_bytes", "to_rgb", "wrap_text", "write_image"]
