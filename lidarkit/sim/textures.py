"""Seeded textures with natural-image statistics, and the mip-mapped atlas the camera simulator samples them from.

A surface's texture is 1/f noise (amplitude spectrum falling as 1/f over spatial frequency in cycles per metre,
so a texture looks alike at any texel size) plus random blobs, rectangles and line edges of its material; every
surface draws from its own seed, so no pattern repeats across the scene. The :class:`TextureAtlas` packs the
textures and their mip levels into one image so a frame's texture lookup is two ``cv2.remap`` calls.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lidarkit.errors import ConfigError


@dataclass(frozen=True)
class Material:
    """Appearance of a surface class: mean grey level, contrast (std of the noise, grey levels), and densities
    (per square metre) of blobs, rectangles and line edges drawn on top."""

    mean: float
    contrast: float
    blobs_per_m2: float
    rects_per_m2: float
    lines_per_m2: float
    shape_size_m: tuple[float, float] = (0.05, 0.8)


MATERIALS: dict[str, Material] = {
    "facade": Material(150.0, 30.0, 0.15, 0.12, 0.05, (0.1, 1.6)),
    "wall": Material(135.0, 22.0, 0.05, 0.02, 0.02, (0.2, 2.0)),
    "road": Material(95.0, 16.0, 0.25, 0.0, 0.03, (0.03, 0.5)),
    "ground": Material(120.0, 22.0, 0.4, 0.02, 0.03, (0.05, 0.8)),
    "pole": Material(110.0, 25.0, 2.0, 0.0, 1.0, (0.02, 0.2)),
    "car": Material(90.0, 35.0, 0.6, 0.6, 0.6, (0.05, 0.6)),
    "trunk": Material(80.0, 25.0, 3.0, 0.0, 1.0, (0.02, 0.15)),
    "foliage": Material(85.0, 35.0, 6.0, 0.0, 0.0, (0.05, 0.4)),
    "occluder": Material(70.0, 35.0, 0.8, 0.5, 0.5, (0.05, 0.6)),
}

_LOW_CUT_PER_M = 1.0 / 6.0  # below this spatial frequency the 1/f spectrum flattens (no huge dark/bright swings)


def natural_texture(rng: np.random.Generator, shape_hw: tuple[int, int], texel_m: float, material: str | Material
                    ) -> np.ndarray:
    """``(h, w)`` uint8 texture of a surface ``h * texel_m`` by ``w * texel_m`` metres: 1/f noise plus shapes."""
    mat = MATERIALS[material] if isinstance(material, str) else material
    h, w = max(int(shape_hw[0]), 2), max(int(shape_hw[1]), 2)
    fy = np.fft.fftfreq(h, d=texel_m)[:, None]
    fx = np.fft.rfftfreq(w, d=texel_m)[None, :]
    amplitude = 1.0 / np.maximum(np.hypot(fx, fy), _LOW_CUT_PER_M)
    amplitude[0, 0] = 0.0
    spectrum = (rng.standard_normal((h, w // 2 + 1)) + 1j * rng.standard_normal((h, w // 2 + 1))) * amplitude
    field = np.fft.irfft2(spectrum, s=(h, w))
    field *= mat.contrast / max(float(field.std()), 1e-12)
    # shapes: drawn anti-aliased on a uint8 layer centred at 128, added as signed offsets
    layer = np.full((h, w), 128, np.uint8)
    area_m2 = h * w * texel_m**2
    lo, hi = mat.shape_size_m
    counts = rng.poisson(area_m2 * np.array([mat.blobs_per_m2, mat.rects_per_m2, mat.lines_per_m2]))
    counts = np.minimum(counts, 400)
    for kind, count in enumerate(counts):
        if count == 0:
            continue
        centre = rng.uniform(0.0, 1.0, (count, 2)) * (w, h)
        size = np.exp(rng.uniform(np.log(lo), np.log(hi), (count, 2))) / texel_m
        angle = rng.uniform(0.0, 180.0, count)
        value = np.clip(128 + rng.choice([-1.0, 1.0], count) * rng.uniform(0.8, 2.5, count) * mat.contrast, 0, 255)
        for c, s, a, v in zip(centre, size, angle, value):
            cx, cy = int(c[0] * 16), int(c[1] * 16)  # 4 fractional bits: subpixel shapes
            if kind == 0:
                cv2.ellipse(layer, (cx, cy), (int(s[0] * 8), int(s[1] * 8)), float(a), 0, 360, float(v), -1,
                            cv2.LINE_AA, 4)
            elif kind == 1:  # axis-aligned rectangles: windows, doors, panels
                x0, y0 = cx - int(s[0] * 8), cy - int(s[1] * 8)
                cv2.rectangle(layer, (x0, y0), (x0 + int(s[0] * 16), y0 + int(s[1] * 16)), float(v), -1,
                              cv2.LINE_AA, 4)
            else:
                length = s[0] * 4.0
                dx, dy = length * np.cos(np.radians(a)) * 16, length * np.sin(np.radians(a)) * 16
                cv2.line(layer, (int(cx - dx), int(cy - dy)), (int(cx + dx), int(cy + dy)), float(v),
                         max(1, int(round(s[1] * 0.1))), cv2.LINE_AA, 4)
    image = mat.mean * rng.uniform(0.8, 1.2) + field + (layer.astype(np.float64) - 128.0)
    return np.clip(image, 0, 255).astype(np.uint8)


def mip_levels(texture: np.ndarray, n_levels: int) -> list[np.ndarray]:
    """``texture`` and up to ``n_levels - 1`` halvings (area averages), each at least 1x1."""
    levels = [texture]
    while len(levels) < n_levels and min(levels[-1].shape) > 1:
        h, w = levels[-1].shape
        levels.append(cv2.resize(levels[-1], ((w + 1) // 2, (h + 1) // 2), interpolation=cv2.INTER_AREA))
    return levels


class AtlasFullError(ConfigError):
    """No room left in a :class:`TextureAtlas` (its owner clears it and regenerates what it needs)."""


class TextureAtlas:
    """One uint8 image holding many textures and their mip levels, grown on demand.

    ``cv2.remap`` addresses at most 32767 rows and columns, so the atlas is ``width`` wide and grows downwards up to
    ``MAX_ROWS``. Textures are packed on shelves whose heights are powers of two (a texture goes to a shelf of the
    next power of two of its height), so tall facades and tiny mip levels do not share a shelf and little space is
    lost. When it is full :meth:`add` raises :class:`AtlasFullError`; :meth:`clear` empties it.
    """

    MAX_ROWS = 32000

    def __init__(self, width: int = 4096):
        self.width = int(width)
        self.image = np.zeros((1024, self.width), np.uint8)
        self.clear()

    def clear(self) -> None:
        """Forget every texture (the memory is kept)."""
        self._shelves: dict[int, tuple[int, int]] = {}  # height bucket -> (shelf y, next free x)
        self._top = 0  # first row no shelf uses

    @property
    def used_rows(self) -> int:
        return self._top

    def add(self, image: np.ndarray) -> tuple[int, int]:
        """Copy ``image`` into free space; returns its top-left ``(x, y)`` in the atlas."""
        h, w = image.shape
        if w > self.width:
            raise ConfigError(f"texture {w} texels wide exceeds the atlas width {self.width}", source="TextureAtlas")
        bucket = max(int(np.ceil(np.log2(max(h, 1)))), 0)
        shelf_h = 2**bucket
        y, x = self._shelves.get(bucket, (-1, self.width))
        if x + w > self.width:  # open a new shelf of this height class
            if self._top + shelf_h > self.MAX_ROWS:
                raise AtlasFullError("the texture atlas is full", source="TextureAtlas")
            y, x = self._top, 0
            self._top += shelf_h
            if self._top > self.image.shape[0]:
                grown = np.zeros((min(max(self.image.shape[0] * 2, self._top), self.MAX_ROWS), self.width), np.uint8)
                grown[: self.image.shape[0]] = self.image
                self.image = grown
        self.image[y : y + h, x : x + w] = image
        self._shelves[bucket] = (y, x + w)
        return x, y


__all__ = ["AtlasFullError", "MATERIALS", "Material", "TextureAtlas", "mip_levels", "natural_texture"]
