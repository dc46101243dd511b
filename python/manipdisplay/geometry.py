"""Shoulder frame -> window pixels, and workspace -> shoulder.

One place for the mapping the display draws with (the test recomputes it
independently from the YAML numbers).
"""
from __future__ import annotations

import math
from typing import Tuple

Vec = Tuple[float, float]


def workspace_to_shoulder(p_ws: Vec, origin_in_shoulder_m: Vec, rot_rad: float) -> Vec:
    """p_shoulder = R(rot) p_workspace + origin (docs/conventions.md)."""
    c, s = math.cos(rot_rad), math.sin(rot_rad)
    return (c * p_ws[0] - s * p_ws[1] + origin_in_shoulder_m[0],
            s * p_ws[0] + c * p_ws[1] + origin_in_shoulder_m[1])


class ScreenMap:
    """Maps shoulder-frame metres to pixels of a window of ``size_px``.

    The pixel pitch comes from the physical screen (width_m / width_px), so a
    smaller window shows the same scene at the same physical size, cropped.
    Screen metres = scale * Mirror * R(rotation) * (p - centre); x to the
    right, y up on the screen (pixel rows grow downwards).
    """

    def __init__(self, screen, mapping, size_px: Tuple[int, int]):
        self.w_px, self.h_px = size_px
        self.px_per_m_x = screen.width_px / screen.width_m
        self.px_per_m_y = screen.height_px / screen.height_m
        self.cx, self.cy = mapping.center_shoulder_m
        a = math.radians(mapping.rotation_deg)
        self.c, self.s = math.cos(a), math.sin(a)
        self.mx = -1.0 if mapping.mirror_x else 1.0
        self.my = -1.0 if mapping.mirror_y else 1.0
        self.scale = mapping.scale

    def to_px(self, p_sh: Vec) -> Tuple[float, float]:
        dx, dy = p_sh[0] - self.cx, p_sh[1] - self.cy
        sx = self.scale * self.mx * (self.c * dx - self.s * dy)
        sy = self.scale * self.my * (self.s * dx + self.c * dy)
        return (self.w_px / 2.0 + sx * self.px_per_m_x, self.h_px / 2.0 - sy * self.px_per_m_y)

    def length_px(self, r_m: float) -> float:
        """A length in shoulder metres as pixels (mean of both pitches: square pixels in practice)."""
        return r_m * self.scale * 0.5 * (self.px_per_m_x + self.px_per_m_y)
