"""Freiburg landmark data: ``world.dat`` (``id x y``) and ``sensor_data.dat`` (odometry + range-bearing).

``sensor_data.dat`` is a sequence of records ``ODOMETRY r1 t r2`` (rad, m, rad), each followed by
zero or more ``SENSOR id range bearing`` (landmark id, m, rad) readings taken after that motion.
Everything is parsed into flat arrays: per-step odometry ``(T, 3)`` and the readings as parallel
``(K,)`` arrays plus their step index, with CSR offsets ``step_offsets`` so that the readings of
step ``t`` are ``slice(step_offsets[t], step_offsets[t + 1])``.

Negative ranges: a range-bearing sensor with additive Gaussian range noise produces negative
readings when the robot stands (almost) on a landmark; the Stachniss copy holds one (-0.035 m to
landmark 7, last step, robot within ~0.05 m of it). Policy ``negative_range``:
``"keep"`` (default: keep the value, it is a legal sample of the Gaussian model; flagged in
``negative_range_mask`` and logged), ``"drop"`` (remove the reading, logged) or ``"error"`` (DataError).
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lidarkit.errors import ConfigError, DataError
from lidarkit.textfile import is_number, read_lines

log = logging.getLogger(__name__)

NEGATIVE_RANGE_POLICIES = ("keep", "drop", "error")
WORLD_FILE = "world.dat"
SENSOR_FILE = "sensor_data.dat"


@dataclass(frozen=True)
class LandmarkMap:
    """Landmark ids ``(L,)`` int64 and positions ``(L, 2)`` float64 (m, world frame)."""

    ids: np.ndarray
    positions_xy: np.ndarray


def read_world(path: str | os.PathLike, *, warnings: list[str] | None = None) -> LandmarkMap:
    """Parse ``world.dat``: one ``id x y`` per line, integer unique ids, finite coordinates; ``warnings``: as for
    :func:`lidarkit.textfile.read_lines` (a file cut inside its last number)."""
    ids: list[int] = []
    xy: list[tuple[float, float]] = []
    seen: dict[int, int] = {}
    for lineno, raw in enumerate(read_lines(path, warnings=warnings), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.split()
        where = f"line {lineno}"
        if len(fields) != 3:
            raise DataError(f"expected 'id x y' (3 fields), found {len(fields)}", source=path, location=where)
        lid = _parse_int(fields[0], path, where)
        x, y = (_parse_float(f, path, where) for f in fields[1:])
        if lid in seen:
            raise DataError(f"duplicate landmark id {lid} (first on line {seen[lid]})", source=path, location=where)
        seen[lid] = lineno
        ids.append(lid)
        xy.append((x, y))
    if not ids:
        raise DataError("no landmarks (empty file)", source=path)
    return LandmarkMap(np.asarray(ids, dtype=np.int64), np.asarray(xy, dtype=np.float64).reshape(-1, 2))


class LandmarkData:
    """A Freiburg landmark dataset (``world.dat`` + ``sensor_data.dat``) parsed into arrays.

    ``path_or_dir``: a folder holding both files, or the ``sensor_data.dat`` file itself (the world
    file is then looked up beside it). ``world`` / ``sensor`` override either file (relative paths are
    taken relative to the folder).

    Attributes: ``landmarks`` (LandmarkMap), ``odometry`` ``(T, 3)`` float64 ``[r1_rad, t_m, r2_rad]``,
    ``meas_step`` ``(K,)`` int64 (0-based step each reading follows), ``meas_landmark_id`` ``(K,)``,
    ``meas_landmark_index`` ``(K,)`` (row in ``landmarks``), ``meas_range_m``, ``meas_bearing_rad``
    ``(K,)`` float64, ``meas_line`` ``(K,)`` (1-based line in the sensor file), ``step_offsets`` ``(T+1,)``,
    ``negative_range_mask`` ``(K,)`` bool, ``n_dropped`` (readings removed by the policy).
    """

    def __init__(
        self,
        path_or_dir: str | os.PathLike,
        *,
        world: str | os.PathLike | None = None,
        sensor: str | os.PathLike | None = None,
        negative_range: str = "keep",
    ) -> None:
        if negative_range not in NEGATIVE_RANGE_POLICIES:
            raise ConfigError(
                f"unknown negative_range policy {negative_range!r}; known: {', '.join(NEGATIVE_RANGE_POLICIES)}",
                source="negative_range",
            )
        base = Path(path_or_dir)
        if not base.exists():
            from lidarkit.atomic import missing_reason

            raise DataError(missing_reason(base, "landmark dataset not found"), source=base)
        folder = base if base.is_dir() else base.parent
        sensor_path = Path(sensor) if sensor is not None else (base if base.is_file() else folder / SENSOR_FILE)
        world_path = Path(world) if world is not None else folder / WORLD_FILE
        if not sensor_path.is_absolute() and sensor is not None:
            sensor_path = folder / sensor_path
        if not world_path.is_absolute() and world is not None:
            world_path = folder / world_path
        if base.is_dir() and world is None and sensor is None and not (world_path.is_file() and sensor_path.is_file()):
            _refuse_a_parent_folder(base)
        self.root = folder
        self.world_path = world_path
        self.sensor_path = sensor_path
        self.negative_range_policy = negative_range
        #: files cut inside their last number (world, sensor data), for a run's metrics.json: once each (only logged,
        #: a run on a cut recording recorded nothing)
        self.reader_warnings: list[str] = []
        self.landmarks = read_world(world_path, warnings=self.reader_warnings)
        self._read_sensor(sensor_path, negative_range)

    # ---- parsing ---------------------------------------------------------------------------------
    def _read_sensor(self, path: Path, negative_range: str) -> None:
        known = {int(i): k for k, i in enumerate(self.landmarks.ids)}
        odometry: list[tuple[float, float, float]] = []
        m_step: list[int] = []
        m_id: list[int] = []
        m_range: list[float] = []
        m_bearing: list[float] = []
        m_line: list[int] = []
        n_dropped = 0
        for lineno, raw in enumerate(read_lines(path, warnings=self.reader_warnings), start=1):
            line = raw.strip()
            if not line or line.startswith("#"):
                continue
            fields = line.split()
            kind = fields[0].upper()
            where = f"line {lineno}"
            if kind == "ODOMETRY":
                if len(fields) != 4:
                    raise DataError(f"ODOMETRY needs 3 values (r1 t r2), found {len(fields) - 1}", source=path, location=where)
                odometry.append(tuple(_parse_float(f, path, where) for f in fields[1:]))  # type: ignore[arg-type]
            elif kind == "SENSOR":
                if len(fields) != 4:
                    raise DataError(f"SENSOR needs 3 values (id range bearing), found {len(fields) - 1}", source=path, location=where)
                if not odometry:
                    raise DataError("SENSOR reading before any ODOMETRY record", source=path, location=where)
                lid = _parse_int(fields[1], path, where)
                if lid not in known:
                    raise DataError(
                        f"unknown landmark id {lid} (world file {self.world_path.name} has {_id_list(self.landmarks.ids)})",
                        source=path,
                        location=where,
                    )
                rng_m = _parse_float(fields[2], path, where)
                bearing = _parse_float(fields[3], path, where)
                if rng_m < 0.0:
                    if negative_range == "error":
                        raise DataError(f"negative range {rng_m} to landmark {lid}", source=path, location=where)
                    if negative_range == "drop":
                        log.warning("%s line %d: dropped negative range %g to landmark %d", path, lineno, rng_m, lid)
                        n_dropped += 1
                        continue
                    log.warning("%s line %d: kept negative range %g to landmark %d (Gaussian range noise)", path, lineno, rng_m, lid)
                m_step.append(len(odometry) - 1)
                m_id.append(lid)
                m_range.append(rng_m)
                m_bearing.append(bearing)
                m_line.append(lineno)
            else:
                if not odometry and len(fields) == 3 and all(is_number(f) for f in fields):  # (it called the id '1' a record type)
                    raise DataError("an 'id x y' line of a world (landmark) file, not sensor data: expected a data folder or its "
                                    f"{SENSOR_FILE}", source=path, location=where)
                raise DataError(f"unknown record type {_shown(fields[0])} (expected ODOMETRY or SENSOR)", source=path, location=where)
        if not odometry:
            raise DataError("no ODOMETRY records (empty file)", source=path)
        if not m_range:  # (a run on it went on without a word, its MSE worse than dead reckoning's)
            dropped = f" ({n_dropped} dropped as negative ranges)" if n_dropped else ""
            log.warning("%s: no SENSOR readings in its %d ODOMETRY steps%s: a filter weighing the landmarks it recorded "
                        "(the protocol's default) only predicts from the odometry", path, len(odometry), dropped)
        self.odometry = np.asarray(odometry, dtype=np.float64).reshape(-1, 3)
        self.meas_step = np.asarray(m_step, dtype=np.int64)
        self.meas_landmark_id = np.asarray(m_id, dtype=np.int64)
        self.meas_landmark_index = np.asarray([known[i] for i in m_id], dtype=np.int64)
        self.meas_range_m = np.asarray(m_range, dtype=np.float64)
        self.meas_bearing_rad = np.asarray(m_bearing, dtype=np.float64)
        self.meas_line = np.asarray(m_line, dtype=np.int64)
        self.negative_range_mask = self.meas_range_m < 0.0
        self.n_dropped = n_dropped
        counts = np.bincount(self.meas_step, minlength=len(self.odometry))
        self.step_offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)

    # ---- views -----------------------------------------------------------------------------------
    def __len__(self) -> int:
        """Number of odometry steps T."""
        return int(self.odometry.shape[0])

    @property
    def n_readings(self) -> int:
        return int(self.meas_range_m.shape[0])

    def readings(self, step: int) -> slice:
        """Slice of the flat reading arrays belonging to ``step`` (0 .. len - 1)."""
        if not 0 <= step < len(self.step_offsets) - 1:
            raise DataError(f"step {step} out of range: the data has steps 0..{len(self.step_offsets) - 2}", source=str(self.root))
        return slice(int(self.step_offsets[step]), int(self.step_offsets[step + 1]))

    def __repr__(self) -> str:
        return (
            f"LandmarkData({str(self.root)!r}, steps={len(self)}, readings={self.n_readings}, "
            f"landmarks={len(self.landmarks.ids)})"
        )


def _parse_float(text: str, path: Path | str | os.PathLike, where: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise DataError(f"not a number: {_shown(text)}", source=path, location=where) from None
    if not math.isfinite(value):
        raise DataError(f"non-finite value {_shown(text)}", source=path, location=where)
    if abs(value) > MAX_ABS_VALUE:
        raise DataError(f"value {_shown(text)} beyond {MAX_ABS_VALUE:g} in magnitude: not a distance (m) or angle (rad) of "
                        "this data", source=path, location=where)
    return value


MAX_ABS_VALUE = 1e7  # landmark coordinates, odometry, ranges and bearings: metres and radians of a planar robot


def _refuse_a_parent_folder(folder: Path) -> None:
    """DataError listing the subfolders holding a dataset when ``folder`` holds none itself (the parent of the three
    Freiburg copies read "world.dat: file not found")."""
    held = sorted(p.name for p in folder.iterdir() if p.is_dir() and (p / WORLD_FILE).is_file() and (p / SENSOR_FILE).is_file())
    if held:
        raise DataError(f"no {WORLD_FILE} + {SENSOR_FILE} in this folder; its subfolders {', '.join(held)} hold them: "
                        "give one of those", source=folder)


def _parse_int(text: str, path: Path | str | os.PathLike, where: str) -> int:
    try:
        value = int(text)
    except ValueError:
        number = _parse_float(text, path, where)
        if not number.is_integer():
            raise DataError(f"landmark id is not an integer: {_shown(text)}", source=path, location=where) from None
        value = int(number)
    if not -(2**63) <= value < 2**63:  # the ids are kept as int64
        raise DataError(f"landmark id {_shown(text)} is beyond a 64-bit integer", source=path, location=where)
    return value


def _id_list(ids: np.ndarray, limit: int = 12) -> str:
    """``ids 1..9`` when they run without a gap, else the ids themselves (the first ``limit``)."""
    ids = np.sort(ids)
    if len(ids) > 1 and np.all(np.diff(ids) == 1):
        return f"ids {int(ids[0])}..{int(ids[-1])}"
    shown = ", ".join(str(int(i)) for i in ids[:limit])
    return f"ids {shown}" + (f", ... ({len(ids)} in all)" if len(ids) > limit else "")


def _shown(text: str, limit: int = 40) -> str:
    """A token of a data file as an error message quotes it: at most ``limit`` characters (a 50 MB line is not echoed)."""
    return repr(text) if len(text) <= limit else repr(text[:limit]) + f"... ({len(text)} characters)"


__all__ = ["LandmarkData", "LandmarkMap", "NEGATIVE_RANGE_POLICIES", "read_world"]
