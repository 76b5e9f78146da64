"""``sensor_msgs/PointCloud2`` messages to lidarkit arrays, with every check a recorded bag needs.

kiss-icp's bag loaders read the field layout from the ``PointField`` constants (``FLOAT32 = 7`` ...), which
messages decoded from MCAP schemas without constants lack; lidarkit reads the datatype codes of the ROS
definition directly and adds what kiss-icp leaves out: missing x/y/z fields, a data buffer shorter than the
header says, non-finite per-point times, the unit of the time field, and missing returns at (0, 0, 0), left out as
the point-file readers leave them out (a message of nothing else is refused, as they refuse such a file). Only the
fields read are laid out: padding (``_``) and other fields may repeat; a counted ``intensity`` is read by its first
value, while a repeated x, y, z or intensity, or a time field with several values per point, is refused.

Per-point time fields (the first present of :data:`TIME_FIELDS` whose values differ within the message, or the one
asked for):

* ``time`` float32 seconds relative to the message stamp (Velodyne drivers; negative when the stamp is the
  sweep end), ``t`` uint32 nanoseconds from the sweep start (Ouster drivers), ``timestamp(s)`` as either;
* integer fields are nanoseconds; float fields are seconds, or nanoseconds when larger than 1e15;
* values lying around the message stamp (within :data:`STAMP_LATENCY_S` of it) and more than two sweeps further
  from 0 are absolute time on the stamp's clock (``point_time_convention="absolute_s"``) whatever their size (a
  simulator's clock starts at 0: 100 s read as relative put every sweep 100 s after its stamp); where the stamp does not
  decide (a stamp of 0 or near it, none given, values near neither), values beyond 1e5 s are absolute, the others
  relative to the message stamp (``"relative_s"``); a float32 field cannot hold absolute times (steps of 128 s at
  1.7e9 s): refused;
* a field whose values span more than :data:`MAX_SWEEP_S` in one message is not the points' times (e.g. an
  intensity named by ``time_field=``), nor is an 8- or 16-bit integer field (a ``ring``), nor one that neither follows
  the point order nor turns with the azimuth nor, in its order, traces a scan pattern (an intensity within 1 s): a
  DataError, where it would have deskewed every sweep by nonsense.

A recording's scans share one convention, read from its first scans (:func:`recording_time_convention`: a simulator's
clock starting at 0 leaves its first stamps too near 0 to decide, and their absolute times were read as relative, 0.1-0.2
s off, while the later scans read as absolute); a scan whose own stamp reads its times the other way is a DataError
naming it (read as the others, its sweep would be deskewed seconds away from its stamp).

:func:`checked_point_times` applies the same rules to per-point times read from other files (the kitti reader's
``point_times/``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from lidarkit.errors import DataError
from lidarkit.io.pointfile import at_sensor_origin

TIME_FIELDS = ("time", "t", "timestamp", "timestamps")
_ABSOLUTE_AFTER_S = 1e5
#: Most time (s) between a message stamp and the nearest of its points' absolute times: a driver stamping on receipt
#: lags the sweep end by up to ~0.15 s (the bag reader reads sweeps further away as another clock)
STAMP_LATENCY_S = 1.0
#: Float time stamps above this are nanoseconds (seconds since 1970 stay below it for 30 million years)
NANOSECONDS_AFTER = 1e15
#: Longest plausible sweep (s): spinning LiDARs turn at 5-20 Hz, solid-state ones integrate ~0.1 s.
MAX_SWEEP_S = 1.0
#: Largest share of steps along the point order where a sweep's times go back (one per row: 128 rows of 1024 is 0.1 %).
_MAX_REVERSALS = 0.005
_MIN_POINTS_TO_JUDGE = 100
#: Most median step in direction between points of consecutive times, as a share of the median angle between two
#: points of the cloud, for times to trace a scan pattern: a solid-state sweep binned in space steps 0.02 of it, an
#: intensity (the simulator's, KITTI's) 0.3-1
_SCAN_PATH_STEP_SHARE = 0.1
#: Least share of the stamps' spacing a sweep's point times span: a sensor seeing a quarter of its turn spans 25 %,
#: microseconds read as nanoseconds span 0.1 % (a 0.1 s sweep of 1e-4 s re-timed the ground truth by 50 us)
MIN_SWEEP_SHARE = 0.01
#: ... and shorter than this (s): no scanning LiDAR sweeps in under a millisecond, while a recording throttled to one
#: 0.1 s sweep every 10 s spans 1 % of its stamps' spacing
MIN_SWEEP_S = 1e-3


@dataclass(frozen=True)
class DecodedCloud:
    """One decoded message: ``points_xyz`` (N, 3) float64 without non-finite points nor points at (0, 0, 0),
    ``intensity`` (N,) float32 or None, ``point_times_s`` (N,) float64 or None in ``point_time_convention``,
    ``time_field`` its source; ``n_at_origin`` points at (0, 0, 0) left out and ``flat_time_fields`` the time fields
    ``time_field="auto"`` passed over (one value for every point), for the reader to say once."""

    points_xyz: np.ndarray
    intensity: np.ndarray | None
    point_times_s: np.ndarray | None
    point_time_convention: str
    time_field: str | None
    n_at_origin: int = 0
    flat_time_fields: tuple[str, ...] = ()


def stamp_seconds(stamp: Any) -> float:
    """A ROS 1 (``sec``/``nanosec``, as rosbags names both) or ROS 2 ``builtin_interfaces/Time`` in seconds."""
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def decode_pointcloud2(msg: Any, *, source: str, location: str, time_field: str | None = "auto",
                       all_missing_ok: bool = False, convention: str | None = None,
                       convention_from: str = "the first scans") -> DecodedCloud:
    """Points, intensity and per-point times of a PointCloud2 ``msg`` (any object with its fields).

    ``time_field``: ``"auto"`` (the first of :data:`TIME_FIELDS` whose values differ, the first present when none
    does), a field name, or None to ignore times. Missing returns (NaN, or exactly (0, 0, 0) as Ouster drivers
    write them) are left out with their times and intensities; a message of missing returns only is a DataError
    (it read "empty scan (0 points)" of 5554 points) unless ``all_missing_ok`` (a pass that only looks at the
    times). ``convention``: the per-point time convention of the whole recording (None: this message's own), as
    :func:`checked_point_times` takes it. Every problem raises DataError naming ``source`` (the file) and ``location``
    (topic and message index).
    """
    names = [f.name for f in msg.fields]
    missing = [axis for axis in ("x", "y", "z") if axis not in names]
    if missing and not names and not int(msg.width) * int(msg.height):  # a default-constructed message: no points
        return DecodedCloud(np.empty((0, 3)), None, None, "relative_s", None)
    if missing:
        raise DataError(f"PointCloud2 has no {'/'.join(missing)} field (fields: {', '.join(names) or 'none'})", source=source, location=location)
    unreadable = _unreadable_fields(msg.fields)
    for axis in ("x", "y", "z"):
        if axis in unreadable:
            raise DataError(f"field {axis!r} {unreadable[axis]}: a point's {axis} is not known", source=source, location=location)
    if names.count("intensity") > 1:  # (a counted one is read by its first value)
        raise DataError(f"field 'intensity' {unreadable['intensity']}: which is the points' intensity is not known",
                        source=source, location=location)
    time_fields = _readable_time_fields(names, unreadable, time_field, source, location)
    wanted = {"x", "y", "z", "intensity", *time_fields}
    try:
        dtype = fields_dtype(msg.fields, int(msg.point_step), wanted)
    except (ValueError, TypeError, KeyError) as err:
        raise DataError(f"PointCloud2 field layout not readable ({err})", source=source, location=location) from None
    width, height = int(msg.width), int(msg.height)
    n_points = width * height
    step = int(msg.point_step)
    if n_points and step <= 0:
        raise DataError(f"point_step {step} for {n_points} points", source=source, location=location)
    # rows may be padded (row_step > width x point_step): each row starts row_step bytes after the one before
    row_step = int(getattr(msg, "row_step", 0) or 0) if height > 1 else width * step
    if n_points and row_step < width * step:
        raise DataError(f"row_step {row_step} is less than width {width} x point_step {step}", source=source, location=location)
    data = msg.data
    buffer = np.frombuffer(data if isinstance(data, (bytes, bytearray, memoryview, np.ndarray)) else bytes(data), dtype=np.uint8)
    need = (height - 1) * row_step + width * step if n_points else 0
    if buffer.size < need:
        raise DataError(
            f"data holds {buffer.size} bytes but width x height = {n_points} points of {step} bytes need "
            f"{need} (truncated message)", source=source, location=location,
        )
    if row_step == width * step:
        cloud = np.ndarray(shape=(n_points,), dtype=dtype, buffer=buffer)
    else:
        cloud = np.ndarray(shape=(height, width), dtype=dtype, buffer=buffer, strides=(row_step, step)).reshape(-1)
    if msg.is_bigendian:
        cloud = cloud.view(cloud.dtype.newbyteorder(">"))
    xyz = np.column_stack([cloud["x"], cloud["y"], cloud["z"]]).astype(np.float64)
    keep = np.isfinite(xyz).all(axis=1)  # organized clouds mark missing returns with NaN, or with (0, 0, 0)
    n_at_origin = 0
    if (xyz[:, 0] == 0).any():  # (x alone first, as the point-file readers: most messages have no x exactly 0)
        at_origin = at_sensor_origin(xyz)
        n_at_origin = int(np.count_nonzero(at_origin))
        keep &= ~at_origin  # (kept in the registration, they were points moving with the sensor: 0.45 m of 2.73 m)
    all_kept = bool(keep.all())
    if n_points and not keep.any() and not all_missing_ok:
        n_nan = n_points - n_at_origin
        what = "NaN" if not n_at_origin else "at (0, 0, 0)" if not n_nan else "NaN or at (0, 0, 0)"
        raise DataError(f"all {n_points} points are {what} (missing returns): no point left (--frames can leave the frame out)",
                        source=source, location=location)
    if not all_kept:
        xyz = xyz[keep]
    intensity = None
    if "intensity" in names:  # (a dual-return driver's counted intensity: the first return's)
        intensity = np.asarray(cloud["intensity" if "intensity" in cloud.dtype.names else "intensity_0"], dtype=np.float32)
        intensity = intensity if all_kept else intensity[keep]

    field = time_fields[0] if time_fields else None
    flat: tuple[str, ...] = ()
    if len(time_fields) > 1:
        field, flat = _varying_time_field(time_fields, cloud, None if all_kept else keep)
    if field is None:
        return DecodedCloud(xyz, intensity, None, "relative_s", None, n_at_origin)
    raw = cloud[field] if all_kept else cloud[field][keep]
    if not np.issubdtype(raw.dtype, np.integer):
        bad = np.flatnonzero(~np.isfinite(raw))
        if len(bad):
            first = int(bad[0]) if all_kept else int(np.flatnonzero(keep)[bad[0]])  # numbered in the message, missing returns included
            raise DataError(
                f"per-point time field {field!r} has {len(bad)} NaN or infinite values (first at point {first})",
                source=source, location=location,
            )
    header = getattr(msg, "header", None)
    stamp_s = stamp_seconds(header.stamp) if header is not None and hasattr(header, "stamp") else None
    times, convention = checked_point_times(raw, xyz, what=f"per-point time field {field!r}", within="one message",
                                            hint="time_field= names the right field, none reads no times",
                                            source=source, location=location, stamp_s=stamp_s, convention=convention,
                                            convention_from=convention_from)
    return DecodedCloud(xyz, intensity, times, convention, field, n_at_origin, flat)


def _varying_time_field(present: list[str], cloud: np.ndarray, keep: np.ndarray | None) -> tuple[str, tuple[str, ...]]:
    """``(field, the ones before it passed over)``: the first of the time fields ``present`` whose values over the kept
    points differ (a driver leaving ``time`` at 0 beside a valid ``t`` gave every sweep zero times), else the first."""
    for k, name in enumerate(present):
        values = cloud[name] if keep is None else cloud[name][keep]
        if len(values) < 2 or not (values == values[0]).all():  # (NaN differs from itself: refused as before)
            return name, tuple(present[:k])
    return present[0], ()


def checked_point_times(raw: np.ndarray, xyz: np.ndarray, *, what: str, within: str, hint: str, source: object,
                        location: str, longest_s: float = MAX_SWEEP_S, stamp_s: float | None = None,
                        convention: str | None = None, convention_from: str = "the first scans") -> tuple[np.ndarray, str]:
    """``(times (N,) float64 seconds, convention)`` of finite per-point values ``raw`` (N,) of points ``xyz`` (N, 3), by
    the rules of the module doc (a sweep lasting ``longest_s`` at most; ``stamp_s``: the scan's stamp, None when there is
    none to read the values against); a DataError naming ``what`` and saying ``hint`` when they cannot be the points'
    times (shared: the kitti reader's ``point_times/`` took ring numbers as times). ``convention``: the one the recording's
    first scans decided (:func:`recording_time_convention`, said as ``convention_from``), given to every scan; a scan
    whose stamp clearly reads its times the other way is a DataError (read alike, it was deskewed seconds off)."""
    if np.issubdtype(raw.dtype, np.integer) and raw.dtype.itemsize < 4:  # (ring numbers read as times deskewed by them)
        raise DataError(
            f"{what} is a {8 * raw.dtype.itemsize}-bit integer: too small for times (drivers write "
            f"float seconds or 32/64-bit integer nanoseconds); {hint}", source=source, location=location,
        )
    if raw.dtype.kind == "f" and raw.dtype.itemsize <= 4 and len(raw):
        smallest = float(np.abs(raw).min())  # (every value absolute: relative nanoseconds start near 0)
        if smallest > _ABSOLUTE_AFTER_S:  # (1.7e9 s in float32 steps of 128 s: a sweep read as "all equal" times)
            raise DataError(
                f"{what} is float32 holding times of {smallest:.4g} s and more: float32 cannot hold absolute times (its steps "
                f"are {float(np.spacing(np.float32(smallest))):.3g} s there; drivers write them as float64 or integer "
                f"nanoseconds); {hint}", source=source, location=location,
            )
    times = point_times_seconds(raw)
    span = float(np.ptp(times)) if len(times) else 0.0
    if span > longest_s:
        unit = "integer nanoseconds" if np.issubdtype(raw.dtype, np.integer) else "seconds"
        raise DataError(
            f"{what} spans {span:.6g} s within {within} (read as {unit}; a sweep lasts at most "
            f"{longest_s:g} s): not the points' times ({hint})", source=source, location=location,
        )
    reversals = _time_order_reversals(times, xyz)
    if reversals is not None:
        raise DataError(
            f"{what} does not follow the sweep: its values go back {reversals} times in "
            f"{len(times)} points and do not turn with the azimuth nor trace a scan pattern in their order (an intensity "
            f"or another per-point value): not the points' times ({hint})", source=source, location=location,
        )
    if convention is None:
        return times, point_time_convention(times, stamp_s)
    if len(times) and stamp_s is not None and np.isfinite(stamp_s):
        lo, hi = float(times.min()), float(times.max())
        own = stamp_verdict(lo, hi, stamp_s)
        if own is not None and own != convention:
            off = _sweep_from_stamp(lo, hi, stamp_s, convention)
            raise DataError(
                f"{what} holds {_CONVENTION_WORDS[own]} ({lo:.6f} to {hi:.6f} s, stamp {stamp_s:.6f} s) where the convention "
                f"read from {convention_from} is {_CONVENTION_WORDS[convention]}: read as those, this sweep lies {off:.6g} s "
                f"from its stamp (--frames can leave the scan out)", source=source, location=location,
            )
    return times, convention


_CONVENTION_WORDS = {"absolute_s": "absolute times on the stamps' clock", "relative_s": "times relative to the stamp"}


def _sweep_from_stamp(first_s: float, last_s: float, stamp_s: float, convention: str) -> float:
    """Seconds from ``stamp_s`` to the sweep whose point times run ``first_s`` to ``last_s`` read in ``convention`` (0:
    the stamp lies within it)."""
    if convention == "absolute_s":
        return max(first_s - stamp_s, stamp_s - last_s, 0.0)
    return max(first_s, -last_s, 0.0)


def stamp_verdict(first_s: float, last_s: float, stamp_s: float) -> str | None:
    """The convention the stamp ``stamp_s`` gives a sweep whose point times run ``first_s`` to ``last_s`` (s): the reading
    that places it around the stamp (within :data:`STAMP_LATENCY_S`) where the other places it more than two sweeps
    further; None when both readings place it near (a stamp within a couple of sweeps of 0) or neither does."""
    sweep = last_s - first_s
    as_absolute = _sweep_from_stamp(first_s, last_s, stamp_s, "absolute_s")
    as_relative = _sweep_from_stamp(first_s, last_s, stamp_s, "relative_s")
    if as_absolute <= STAMP_LATENCY_S and as_relative > as_absolute + 2 * sweep:
        return "absolute_s"
    if as_relative <= STAMP_LATENCY_S and as_absolute > as_relative + 2 * sweep:
        return "relative_s"
    return None


def recording_time_convention(stamps_s: np.ndarray, firsts_s: np.ndarray, lasts_s: np.ndarray) -> str:
    """The one convention of a recording's per-point times, from its first sweeps: sweep ``k`` stamped ``stamps_s[k]``
    with times from ``firsts_s[k]`` to ``lasts_s[k]`` (s, as stored). Judged per scan, a simulator's clock starting at 0
    read its first sweeps' absolute times as relative (their stamps within two sweeps of 0 decide nothing), 0.1-0.2 s
    off, while the later ones read as absolute. So: the stamps' verdicts (:func:`stamp_verdict`; the more common one);
    where none decides and both readings place every sweep near its stamp, the reading in which the sweeps keep their
    place against their stamps (absolute times move with the stamps, relative ones do not); else the size (any value
    beyond 1e5 s: absolute)."""
    stamps_s, firsts_s, lasts_s = (np.asarray(a, dtype=np.float64) for a in (stamps_s, firsts_s, lasts_s))
    if not len(stamps_s):
        return "relative_s"
    verdicts = [stamp_verdict(a, b, s) for a, b, s in zip(firsts_s, lasts_s, stamps_s) if np.isfinite(s)]
    n_absolute, n_relative = verdicts.count("absolute_s"), verdicts.count("relative_s")
    if n_absolute or n_relative:
        if n_absolute != n_relative:
            return "absolute_s" if n_absolute > n_relative else "relative_s"
        return next(v for v in verdicts if v is not None)
    near = [max(_sweep_from_stamp(a, b, s, "absolute_s"), _sweep_from_stamp(a, b, s, "relative_s")) <= STAMP_LATENCY_S
            for a, b, s in zip(firsts_s, lasts_s, stamps_s)]
    if len(stamps_s) > 1 and all(near) and np.isfinite(stamps_s).all():
        mids = 0.5 * (firsts_s + lasts_s)
        moving_absolute, moving_relative = _spread(mids - stamps_s), _spread(mids)
        if moving_absolute < _KEEPS_PLACE * moving_relative:
            return "absolute_s"
        if moving_relative < _KEEPS_PLACE * moving_absolute:
            return "relative_s"
    return "absolute_s" if float(np.max(np.abs(np.concatenate([firsts_s, lasts_s])))) > _ABSOLUTE_AFTER_S else "relative_s"


#: Most share of the other reading's spread of the sweeps against their stamps for one reading to keep them in place
_KEEPS_PLACE = 0.25


def _spread(values: np.ndarray) -> float:
    """Median distance of ``values`` (n,) from their median (a first sweep begun mid-rotation does not count)."""
    return float(np.median(np.abs(values - np.median(values))))


def point_time_convention(times: np.ndarray, stamp_s: float | None = None) -> str:
    """``"absolute_s"`` or ``"relative_s"`` for per-point times ``times`` (N,) in seconds of a scan stamped ``stamp_s``.

    Read against the stamp (:func:`stamp_verdict`): times around it (the sweep within :data:`STAMP_LATENCY_S`) that lie
    more than two sweeps further from 0 are absolute on its clock, whatever their size (a simulator's 100 s were read as relative, placing
    the sweeps 100 s after their stamps). Where both readings place the sweep near (a stamp within a couple of sweeps
    of 0), or neither does, or no stamp is given, the size decides: beyond 1e5 s absolute, else relative.
    """
    if not len(times):
        return "relative_s"
    lo, hi = float(times.min()), float(times.max())
    verdict = stamp_verdict(lo, hi, stamp_s) if stamp_s is not None and np.isfinite(stamp_s) else None
    if verdict is not None:
        return verdict
    return "absolute_s" if max(abs(lo), abs(hi)) > _ABSOLUTE_AFTER_S else "relative_s"


def point_times_seconds(raw: np.ndarray) -> np.ndarray:
    """``(N,)`` float64 seconds of per-point time values ``raw`` (N,): integers are nanoseconds, floats seconds (or
    nanoseconds above :data:`NANOSECONDS_AFTER`)."""
    if np.issubdtype(raw.dtype, np.integer):
        return raw.astype(np.float64) * 1e-9
    times = raw.astype(np.float64)
    if len(times) and float(np.abs(times).max()) > NANOSECONDS_AFTER:
        times = times * 1e-9
    return times


def time_unit_read(dtype: np.dtype) -> str:
    """The unit per-point time values of ``dtype`` are read in, in words."""
    return "integer nanoseconds" if np.issubdtype(dtype, np.integer) else "seconds"


def check_sweep_span(span_s: float, spacing_s: float | None, *, what: str, unit: str, over: str, hint: str, source: object,
                     location: str | None = None) -> None:
    """DataError when point times spanning ``span_s`` per sweep (a median ``over`` some scans) cover less than
    :data:`MIN_SWEEP_SHARE` of the ``spacing_s`` between the scans' stamps (None: not known) and less than
    :data:`MIN_SWEEP_S`: microseconds read as nanoseconds (a uint32 ``t`` in us) gave sweeps of 1e-4 s and re-timed the
    ground truth without a word. ``unit``: how they were read."""
    if 0 < span_s < MIN_SWEEP_S and (spacing_s is None or span_s < MIN_SWEEP_SHARE * spacing_s):
        stamped = "" if spacing_s is None else (f" while the scans are stamped {spacing_s:.3g} s apart ({100 * span_s / spacing_s:.3g} % "
                                                f"of it)")
        raise DataError(
            f"{what}: sweeps of {span_s:.3g} s ({over}){stamped}, under {MIN_SWEEP_S:g} s: read as {unit}, the unit looks "
            f"like microseconds (or the values are 1000x too small); {hint}", source=source, location=location,
        )


def _time_order_reversals(times: np.ndarray, xyz: np.ndarray) -> int | None:
    """How often ``times`` (N,) go back along the point order, when they are no sweep's times; None when they are.

    A sweep's times rise (or fall) along the firing order, going back only at each row of an organized cloud
    (:data:`_MAX_REVERSALS` of the steps at most), or turn with the azimuth of a spinning sensor (points
    ``xyz`` (N, 3)), or, taken in their order, trace the scan pattern of a solid-state one (:func:`_traces_scan_path`);
    an intensity within 1 s does none of these (it passed as times, deskewing every sweep by it).
    """
    span = float(np.ptp(times)) if len(times) else 0.0
    if len(times) < _MIN_POINTS_TO_JUDGE or span == 0.0:
        return None
    steps = np.diff(times)
    big = np.abs(steps) > 0.01 * span  # (a firing block's per-channel offsets are microseconds)
    reversals = min(np.count_nonzero(big & (steps > 0)), np.count_nonzero(big & (steps < 0)))
    if reversals <= _MAX_REVERSALS * len(steps):
        return None
    azimuth = np.arctan2(xyz[:, 1], xyz[:, 0])
    phase = 2 * np.pi * (times - times.min()) / span  # one turn per sweep, either way round
    turning = max(abs(np.exp(1j * (azimuth - phase)).mean()), abs(np.exp(1j * (azimuth + phase)).mean()))
    return None if turning > 0.5 or _traces_scan_path(times, xyz) else int(reversals)


def _traces_scan_path(times: np.ndarray, xyz: np.ndarray) -> bool:
    """Whether the points ``xyz`` (N, 3), taken in the order of ``times`` (N,), trace a scan pattern: each next time's
    point a small step in direction from the one before. A solid-state sensor (Livox) sweeps no azimuth, and its points
    stored in another order (binned in space) were refused as "an intensity"; an intensity's next value lies anywhere
    in the field of view. Judged by direction (an intensity falling with range would trace a path in space) over
    the distinct values, ties taken in a fixed random order (the stored order of equal values is a path of its own)."""
    rng = np.random.default_rng(0)
    shuffled = rng.permutation(len(times))
    order = shuffled[np.argsort(times[shuffled], kind="stable")]
    ordered_times = times[order]
    order = order[np.r_[True, ordered_times[1:] != ordered_times[:-1]]]
    if len(order) < _MIN_POINTS_TO_JUDGE:
        return False
    with np.errstate(invalid="ignore", divide="ignore"):
        directions = np.nan_to_num(xyz / np.linalg.norm(xyz, axis=1, keepdims=True))
    step_rad = np.median(_angles_between(directions[order[:-1]], directions[order[1:]]))
    spread_rad = np.median(_angles_between(directions, directions[rng.permutation(len(directions))]))
    return bool(spread_rad > 0 and step_rad <= _SCAN_PATH_STEP_SHARE * spread_rad)


def _angles_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles (rad) between the unit vectors of rows of ``a`` and ``b`` (M, 3)."""
    return np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1.0, 1.0))


#: sensor_msgs/PointField datatype codes
POINTFIELD_DTYPES = {1: "i1", 2: "u1", 3: "<i2", 4: "<u2", 5: "<i4", 6: "<u4", 7: "<f4", 8: "<f8"}
#: The name PCL gives padding fields (``x y z _ intensity``), often repeated: never read
PADDING_FIELD = "_"


def fields_dtype(fields: Any, point_step: int, wanted: set[str] | None = None) -> np.dtype:
    """Structured little-endian dtype of a PointCloud2 point; fields with ``count > 1`` become ``name_0, name_1, ...``.

    ``wanted``: the field names to hold (None: all). Fields named ``_`` (padding) are left out, and so are fields not
    wanted, so that padding or a repeated field the reader does not use cannot make the layout unreadable; a wanted
    name given twice is a ValueError (which one is meant is not known).
    """
    names, formats, offsets = [], [], []
    for i, field in enumerate(fields):
        code = int(field.datatype)
        if code not in POINTFIELD_DTYPES:
            raise ValueError(f"field {field.name!r} has unknown datatype code {code}")
        base = np.dtype(POINTFIELD_DTYPES[code])
        count = int(field.count) if int(field.count) > 0 else 1
        end = int(field.offset) + count * base.itemsize
        if end > point_step:
            raise ValueError(f"fields end at byte {end} but point_step is {point_step}")
        name = field.name or f"unnamed_field_{i}"
        if name == PADDING_FIELD or (wanted is not None and name not in wanted):
            continue
        for a in range(count):
            names.append(name if count == 1 else f"{name}_{a}")
            formats.append(base)
            offsets.append(int(field.offset) + a * base.itemsize)
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise ValueError(f"duplicate field names ({', '.join(repeated)})")
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": point_step})


def _unreadable_fields(fields: Any) -> dict[str, str]:
    """Why a field cannot be read as one value per point, by name: given more than once, or with ``count > 1``."""
    counts: dict[str, list[int]] = {}
    for field in fields:
        counts.setdefault(str(field.name), []).append(int(field.count))
    why = {}
    for name, given in counts.items():
        if len(given) > 1:
            why[name] = f"is given {len(given)} times in the field list"
        elif given[0] > 1:
            why[name] = f"has count {given[0]} ({given[0]} values per point)"
    return why


def _readable_time_fields(names: list[str], unreadable: dict[str, str], wanted: str | None, source: str,
                          location: str) -> list[str]:
    """The per-point time fields to consider: the one named, or under ``"auto"`` those of :data:`TIME_FIELDS` present
    and read as one value per point, in that order; DataError for a named field, or the only ones present, that are
    not (a ``t`` of count 2 may be a 64-bit time in two halves: reading either as the time would deskew by nonsense)."""
    if wanted is None or wanted in ("", "none"):
        return []
    if wanted == PADDING_FIELD:  # (left out of every layout: reading it was a numpy traceback)
        raise DataError(f"{PADDING_FIELD!r} is padding (PCL's filler bytes), not a per-point time field (fields: "
                        f"{', '.join(names)})", source=source, location=location)
    if wanted != "auto" and wanted not in names:
        raise DataError(f"no per-point time field {wanted!r} (fields: {', '.join(names)})", source=source, location=location)
    present = [wanted] if wanted != "auto" else [f for f in TIME_FIELDS if f in names]
    readable = [f for f in present if f not in unreadable]
    if present and not readable:
        raise DataError(f"per-point time field {present[0]!r} {unreadable[present[0]]}: which is the point's time is not known "
                        "(time_field= names another field, none reads no times)", source=source, location=location)
    return readable


__all__ = ["MAX_SWEEP_S", "MIN_SWEEP_S", "MIN_SWEEP_SHARE", "NANOSECONDS_AFTER", "TIME_FIELDS", "DecodedCloud", "check_sweep_span",
           "STAMP_LATENCY_S", "checked_point_times", "decode_pointcloud2", "fields_dtype", "point_time_convention",
           "point_times_seconds", "recording_time_convention", "stamp_verdict", "stamp_seconds", "time_unit_read"]
