"""``local_plane``: slope-following ground segmentation on a grid of local plane fits (the default).

A height threshold relative to the sensor keeps uphill ground and cuts downhill objects. Here the ground
is found where it is, cell by cell, and every point is judged by its height above the *local* ground:

1. Bin the points into ``cell_size_m`` columns; each cell's floor is its ``floor_rank``-th lowest z (one
   low outlier, e.g. a mirror reflection below the road, does not set the floor).
2. A cell holds visible ground if its floor is not higher than any other floor within ``window_m`` plus
   ``max_slope`` times their distance (plus ``step_tolerance_m``): a slope-limited lower envelope, propagated
   cell to cell. The floor of a car roof, a tree crown or a wall whose foot is hidden rises too steeply above
   the ground around it.
3. Seeds are the points within ``seed_band_m`` of the floor of ground cells; a plane ``z = a x + b y + c``
   is fitted by least squares to the seeds of the 3 x 3 cells around each cell (ridge-regularised slope,
   rejected if steeper than ``max_slope``; then the flat envelope height is used). The fit is repeated
   without the cells that hold an object (a point ``structure_height_m`` above the plane) and with the
   seeds within ``refit_band_m`` of the first plane: the foot of a wall would tilt and lift the plane.
4. A point is ground if it lies less than ``threshold_m`` above its cell's plane; in a cell that also holds an
   object (a point ``structure_height_m`` above the plane) the bar is ``structure_threshold_m``, so that the
   foot of a wall or a car, hit by many rings at short range, is not taken for ground.

All steps are array operations over points and over a dense cell grid (window offsets loop, not points).
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from lidarkit.errors import ConfigError
from lidarkit.registration.ground.base import GroundConfig, GroundSegmenter, register_ground_segmenter
from lidarkit.resources import check_memory

#: Peak memory per grid cell: the floors, the envelope and the plane-fit moments, sums and solves (~400 B measured on
#: KITTI scans at 0.15-0.25 m cells).
GRID_BYTES_PER_CELL = 500.0
#: Most cell updates of the slope-limited envelope (cells x ceil(window_m / cell_size_m) passes) a cloud may take:
#: ~1.8e7 a second were measured, so about half a minute (the default 1 m cells on a KITTI scan take 2.4e5; 0.05 m
#: cells took 1.9e9, 103 s and 2.6 GB).
MAX_ENVELOPE_CELL_UPDATES = 5e8


class LocalPlaneConfig(GroundConfig):
    cell_size_m: float = Field(1.0, gt=0, description="edge of the square grid cells (m)")
    window_m: float = Field(15.0, gt=0, description="floors this far (m, along the grid) bound a cell's floor")
    max_slope: float = Field(
        0.4, gt=0, description="steepest ground (rise over run) in the sensor frame: a vehicle pitched on a 0.25 downslope sees "
        "the next upslope nearly twice as steep (0.3 left such slopes as 'objects' on the open hills, 8.6 % drift on one seed)"
    )
    step_tolerance_m: float = Field(0.25, ge=0, description="a floor may rise this much above the slope-limited envelope (m)")
    floor_rank: int = Field(2, ge=1, description="a cell's floor is its k-th lowest point (1: the lowest)")
    seed_band_m: float = Field(0.2, gt=0, description="points within this of their ground cell's floor seed the plane fit (m)")
    refit_band_m: float = Field(0.1, gt=0, description="second fit: seeds within this of the first plane (m)")
    threshold_m: float = Field(0.2, gt=0, description="points less than this above the local plane are ground (m)")
    structure_height_m: float = Field(0.7, gt=0, description="a cell with a point this high above its plane holds an object (m)")
    structure_threshold_m: float = Field(
        0.05, gt=0, description="in a cell holding an object, only points less than this above the plane are ground (m): the foot of a wall is not"
    )
    ridge: float = Field(1.0, ge=0, description="ridge weight pulling fitted slopes towards 0 (in points x m^2)")
    max_range_m: float = Field(150.0, gt=0, description="points farther (horizontally) are never ground")


def _fit_planes(xy: np.ndarray, z: np.ndarray, cells: np.ndarray, nx: int, ny: int, c: LocalPlaneConfig) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares plane ``z = a x + b y + c`` per cell over the seeds of its 3 x 3 cells: ``(n_cells, 3)`` and fit mask."""
    n_cells = nx * ny
    x, y = xy[:, 0], xy[:, 1]
    moments = np.stack(
        [np.bincount(cells, weights=w, minlength=n_cells) for w in (x * x, x * y, y * y, x, y, np.ones_like(x), x * z, y * z, z)], axis=0
    ).reshape(9, nx, ny)
    padded = np.pad(moments, ((0, 0), (1, 1), (1, 1)))
    window = sum(padded[:, 1 + dx : 1 + dx + nx, 1 + dy : 1 + dy + ny] for dx in (-1, 0, 1) for dy in (-1, 0, 1))
    sxx, sxy, syy, sx, sy, n, sxz, syz, sz = window.reshape(9, -1)
    A = np.stack([np.stack([sxx + c.ridge, sxy, sx], -1), np.stack([sxy, syy + c.ridge, sy], -1), np.stack([sx, sy, n], -1)], axis=1)
    b = np.stack([sxz, syz, sz], axis=-1)
    fit = n >= 3
    coef = np.zeros((n_cells, 3))
    if fit.any():
        coef[fit] = np.linalg.solve(A[fit], b[fit][..., None])[..., 0]
    fit &= np.hypot(coef[:, 0], coef[:, 1]) <= c.max_slope
    return coef, fit


def _plane_z(coef: np.ndarray, fit: np.ndarray, reference: np.ndarray, cells: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Local ground height under each point: its cell's plane, or the flat reference where no plane was fitted."""
    return np.where(fit[cells], coef[cells, 0] * xy[:, 0] + coef[cells, 1] * xy[:, 1] + coef[cells, 2], reference[cells])


def _cell_max(values: np.ndarray, cells: np.ndarray, n_cells: int) -> np.ndarray:
    out = np.full(n_cells, -np.inf)
    np.maximum.at(out, cells, values)
    return out


def check_grid_size(nx: int, ny: int, config: LocalPlaneConfig) -> None:
    """Refuse a grid too large to build (memory) or to propagate the envelope over (work) before it is allocated: a
    small ``cell_size_m`` squares the cell count (0.01 m ran numpy out of memory, 0.05 m took 103 s and 2.6 GB)."""
    c = config
    passes = int(np.ceil(c.window_m / c.cell_size_m))
    grid = (f"a {nx} x {ny} cell grid (cell_size_m={c.cell_size_m:g} over the cloud within max_range_m={c.max_range_m:g})")
    source = "ground segmenter 'local_plane' (cell_size_m / max_range_m / window_m)"
    check_memory(GRID_BYTES_PER_CELL * nx * ny, grid, source)
    updates = float(nx) * ny * passes
    if updates > MAX_ENVELOPE_CELL_UPDATES:
        raise ConfigError(f"{grid} with window_m={c.window_m:g} ({passes} envelope passes) is {updates:.2g} cell updates, "
                          f"more than {MAX_ENVELOPE_CELL_UPDATES:.0e} (about half a minute): raise cell_size_m or lower "
                          "max_range_m or window_m", source=source)


def local_plane_ground_mask(points_xyz: np.ndarray, config: LocalPlaneConfig) -> np.ndarray:
    """``(N,)`` bool ground mask of an ``(N, 3)`` cloud (sensor frame, z roughly up); see the module docstring."""
    c = config
    pts = np.asarray(points_xyz, dtype=np.float64)
    mask = np.zeros(len(pts), dtype=bool)
    # (horizontal range, as the setting says: a square box made ground of points up to 1.41 x max_range_m away)
    use = np.flatnonzero((np.hypot(pts[:, 0], pts[:, 1]) <= c.max_range_m) & np.isfinite(pts).all(axis=1))
    if len(use) == 0:
        return mask
    p = pts[use]
    cell = c.cell_size_m
    ij = np.floor(p[:, :2] / cell).astype(np.int64)
    ij -= ij.min(axis=0)
    nx, ny = (ij.max(axis=0) + 1).tolist()
    check_grid_size(nx, ny, c)
    flat = ij[:, 0] * ny + ij[:, 1]
    n_cells = nx * ny

    # 1. floor of each cell: the floor_rank-th lowest z
    order = np.lexsort((p[:, 2], flat))
    sorted_cells = flat[order]
    starts = np.flatnonzero(np.r_[True, sorted_cells[1:] != sorted_cells[:-1]])
    counts = np.diff(np.r_[starts, len(order)])
    pick = starts + np.minimum(c.floor_rank, counts) - 1
    floor = np.full(n_cells, np.inf)
    floor[sorted_cells[starts]] = p[order[pick], 2]
    floor = floor.reshape(nx, ny)

    # 2. slope-limited lower envelope of the floors, propagated cell to cell (through empty cells too)
    envelope = floor.copy()
    steps = [(dx, dy, float(np.hypot(dx, dy)) * cell * c.max_slope) for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy]
    for _ in range(int(np.ceil(c.window_m / cell))):
        padded = np.pad(envelope, 1, constant_values=np.inf)
        for dx, dy, rise in steps:
            np.minimum(envelope, padded[1 + dx : 1 + dx + nx, 1 + dy : 1 + dy + ny] + rise, out=envelope)
    occupied = np.isfinite(floor)
    ground_cell = occupied & (floor <= envelope + c.step_tolerance_m)
    reference = np.where(ground_cell, floor, np.minimum(floor, envelope)).ravel()  # flat fallback height

    # 3. plane fit to the seeds of the 3 x 3 ground cells around each cell (coordinates relative to the cell grid),
    #    then again without the cells that hold an object (the foot of a wall, hit by ring after ring at short
    #    range, tilts and lifts a plane) and keeping the seeds within refit_band_m of the first plane
    rel = p[:, :2] - (np.floor(p[:, :2] / cell).min(axis=0)) * cell
    in_ground_cell = ground_cell.ravel()[flat]
    seed = in_ground_cell & (p[:, 2] <= floor.ravel()[flat] + c.seed_band_m)
    coef, fit = _fit_planes(rel[seed], p[seed, 2], flat[seed], nx, ny, c)
    height = p[:, 2] - _plane_z(coef, fit, reference, flat, rel)
    tall = _cell_max(height, flat, n_cells) >= c.structure_height_m
    seed = in_ground_cell & ~tall[flat] & (np.abs(height) <= c.refit_band_m)
    coef, fit = _fit_planes(rel[seed], p[seed, 2], flat[seed], nx, ny, c)
    # 4. height above the local ground
    height = p[:, 2] - _plane_z(coef, fit, reference, flat, rel)
    tall = _cell_max(height, flat, n_cells) >= c.structure_height_m
    threshold = np.where(tall[flat], c.structure_threshold_m, c.threshold_m)
    mask[use] = height < threshold
    return mask


@register_ground_segmenter("local_plane")
class LocalPlaneSegmenter(GroundSegmenter):
    """Grid of local plane fits under a slope-limited envelope: height above the local ground (slopes, hills)."""

    Config = LocalPlaneConfig
    heights_from_sensor = False  # heights against the points themselves

    def _segment(self, points_xyz: np.ndarray) -> np.ndarray:
        return local_plane_ground_mask(points_xyz, self.config)
