"""ROS bags and MCAP files as scan sequences, through kiss-icp's ``rosbag`` and ``mcap`` dataloaders.

``open_dataset("rosbag", path, topic=...)`` reads a ROS 1 ``.bag`` (or a folder of split ``.bag`` files, each part
beginning where the one before ends: separate recordings in one folder are refused) or a ROS 2 bag folder (``metadata.yaml``, sqlite3 or mcap storage); ``open_dataset("mcap", path, topic=...)`` a
standalone ``.mcap`` file (ROS 2 messages, or ROS 1 ones as an MCAP converted from a ``.bag`` holds). kiss-icp's
loaders open the files; lidarkit checks the topic first (kiss-icp prints and exits on a missing one) and decodes
each message with :func:`lidarkit.io.pointcloud2.decode_pointcloud2`.

A topic is one sensor's: a message in another ``header.frame_id`` than the first is a DataError (two sensors on one
topic read as one made a 60 m path of a 3 m drive).

Per scan: ``timestamp_s`` is the message header stamp; ``stamp_instant`` says which instant of the sweep that
stamp is, read from the per-point times (relative times starting at 0: the sweep start; ending at 0: the end); a stamp
at no such instant (a driver stamping on receipt, after the sweep end) is placed by ``sweep_offset_s``. The per-point
times of every message are read in one convention (absolute or relative to the stamp), the topic's, read from its first
scans (:func:`~lidarkit.io.pointcloud2.recording_time_convention`).
Ground truth: a ``nav_msgs/Odometry`` topic (``ground_truth_topic``; found automatically when there is one), read
in header-stamp order, one pose per scan (by count when each pose lies as far from its scan as the others, also for a
selection of scans; else the pose nearest the place in the sweep where the poses are stamped), expressed relative to
nothing (as recorded; odometry of another frame than the clouds' is said in ``reader_warnings``); its
``meta["pose_instant"]`` is read from its stamps against the sweep's point times (a sweep lasting from its first to its
last point where that is not the stamps' spacing: :func:`sweep_length`). At another instant of the sweep
(:meth:`_BagScans.ground_truth_at_instant`) it is interpolated, unless the recording keeps the poses at that instant
beside it (:func:`sweep_instant_topic`: the simulator's bags do).

Access is sequential (a bag is a stream); reading an earlier index reopens the bag.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import threading
import warnings
from collections.abc import Iterator
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError, DataError
from lidarkit.io.base import INSTANT_FRACTION, Scan, checked_index, checked_indices, classify_instant, sweep_length
from lidarkit.io.pointcloud2 import (MAX_SWEEP_S, POINTFIELD_DTYPES, DecodedCloud, check_sweep_span, decode_pointcloud2,
                                     recording_time_convention, stamp_seconds, time_unit_read)
from lidarkit.trajectory import Trajectory

log = logging.getLogger(__name__)

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
ROS_EXTRA = "pip install 'lidarkit[ros]'  (rosbags, mcap, mcap-ros2-support)"
#: first bytes of a ROS 1 bag (format 2.0)
ROS1_MAGIC = b"#ROSBAG "


def sweep_instant_topic(ground_truth_topic: str, instant: str) -> str:
    """The topic beside ``ground_truth_topic`` that holds the pose at ``instant`` (start, mid, end) of every sweep
    (``geometry_msgs/PoseStamped``, stamped there), as the simulator's bags keep it: ``/ground_truth/sweep_mid``."""
    return f"{ground_truth_topic.rstrip('/')}/sweep_{instant}"


def require_modules(modules: dict[str, str], kind: str) -> None:
    """ConfigError naming the pip line when a module a reader needs is not installed."""
    import importlib.util

    for module, pip_line in modules.items():
        try:
            found = importlib.util.find_spec(module) is not None
        except (ImportError, ValueError):
            found = False
        if not found:
            raise ConfigError(f"the {kind} reader needs the Python package {module.split('.')[0]!r}: {pip_line}", source=f"{kind} dataset")


@contextlib.contextmanager
def guarded_loader(kind: str, source: str, location: str | None = None) -> Iterator[None]:
    """Run a kiss-icp loader call so that it can neither print to stdout nor end the process, nor show Python warnings.

    kiss-icp's loaders print and call ``exit()`` on problems they find; lidarkit checks first, and anything left
    becomes a DataError carrying what the loader printed. Its warnings (numpy's six lines on the comment lines of
    every TUM folder) are logged at debug level, as what it prints; the caller's filters still decide which are
    raised.
    """
    out = io.StringIO()
    caught: list[warnings.WarningMessage] = []
    # warnings are caught in the main thread only (the loaders warn as they open): catch_warnings is process-wide, and
    # from the reading-ahead thread it hid the main thread's warnings and, overlapping, left its hook in place
    catching = warnings.catch_warnings(record=True) if threading.current_thread() is threading.main_thread() else None
    try:
        with contextlib.redirect_stdout(out), (catching or contextlib.nullcontext()) as recorded:
            caught = recorded if recorded is not None else caught
            yield
    except SystemExit:
        said = " ".join(out.getvalue().split()) or "no message"
        raise DataError(f"kiss-icp's {kind} loader gave up: {said}", source=source, location=location) from None
    except (AssertionError, OSError, IndexError, KeyError, ValueError, StopIteration) as err:
        raise DataError(f"kiss-icp's {kind} loader failed: {type(err).__name__}: {err}", source=source, location=location) from None
    finally:
        if out.getvalue().strip():
            log.debug("%s loader said: %s", kind, out.getvalue().strip())
        for caught_warning in caught:
            log.debug("%s loader warned: %s: %s", kind, caught_warning.category.__name__, caught_warning.message)


class _BagScans:
    """What the ROS bag and MCAP readers share: sequential reading, decoding, stamps and ground truth."""

    kind = "bag"

    def __init__(self, path: str | os.PathLike, topic: str | None, ground_truth_topic: str | None, time_field: str | None):
        self.path = Path(path)
        #: what the reader found and left out or could not place, for the run's warnings as well as the log (once each)
        self.reader_warnings: list[str] = []
        self._warned: set[str] = set()
        #: why the sweeps cannot be placed against the stamps although the scans carry point times (another clock)
        self._timing_problem: str | None = None
        if not self.path.exists():
            raise DataError("bag not found", source=self.path)
        # None (a spec's null) is the default, as for every option; "none" (or "") reads no point times ("None", "NONE",
        # "Auto": the same words in other cases, not field names)
        time_field = _option_word(time_field, ("none", "auto"))
        self.time_field = "auto" if time_field is None else time_field
        self._time_fields_read: set[str] = set()  # the fields time_field resolved to in the messages decoded
        self._next = 0
        self._stream: Iterator[tuple[int, Any]] | None = None
        self._stamps: dict[int, float] = {}
        self._stamps_checked = False  # one pass over the topic counted its messages and checked their stamps
        self._cloud_frame: str | None = None  # the first cloud's header.frame_id, once a message was read
        self._cloud_field_types: dict[str, int] = {}  # the first cloud decoded's fields: their PointField datatype codes
        self._last_stamp: tuple[int, float] | None = None
        topics = self._list_topics()  # {topic: msgtype}
        self._topics = topics
        self._instant_poses: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # topic: what _poses_at_instant read
        clouds = sorted(t for t, m in topics.items() if m == POINTCLOUD2)
        listing = ", ".join(f"{t} ({m})" for t, m in sorted(topics.items())) or "none"
        topic = _topic_named(topic, topics)
        if topic:
            if topic not in topics:
                raise DataError(f"no topic {topic!r}; topics present: {listing}", source=self.path)
            if topics[topic] != POINTCLOUD2:
                raise DataError(f"topic {topic!r} carries {topics[topic]}, not {POINTCLOUD2}; topics present: {listing}", source=self.path)
        elif not clouds:
            raise DataError(f"no {POINTCLOUD2} topic; topics present: {listing}", source=self.path)
        elif len(clouds) > 1:
            raise DataError(f"several {POINTCLOUD2} topics ({', '.join(clouds)}): choose one with topic=...", source=self.path)
        self.topic = topic or clouds[0]
        odometry = sorted(t for t, m in topics.items() if m == ODOMETRY)
        ground_truth_topic = _topic_named(_option_word(ground_truth_topic, ("none",)), topics)
        if ground_truth_topic == "none":  # no ground truth (None: the one odometry topic, if there is one)
            ground_truth_topic = ""
        if ground_truth_topic:
            if topics.get(ground_truth_topic) != ODOMETRY:
                raise DataError(f"ground_truth_topic {ground_truth_topic!r} is not a {ODOMETRY} topic; topics present: {listing}", source=self.path)
            self.ground_truth_topic: str | None = ground_truth_topic
        elif ground_truth_topic is None and len(odometry) == 1:
            self.ground_truth_topic = odometry[0]
        elif ground_truth_topic is None and len(odometry) > 1:  # which one is the ground truth is the user's call
            raise DataError(f"several {ODOMETRY} topics ({', '.join(odometry)}): choose the ground truth with ground_truth_topic=... "
                            "(or ground_truth_topic=none)", source=self.path)
        else:
            self.ground_truth_topic = None
        self.name = f"{self.kind}:{self.path.name}{self.topic}"
        self._open_loader()

    def __repr__(self) -> str:
        """One line naming the recording (it was ``<... object at 0x...>``)."""
        scans = getattr(self, "n_scans", None)
        return (f"{type(self).__name__}({str(self.path)!r}, topic {getattr(self, 'topic', None)!r}, "
                f"{'?' if scans is None else scans} scans, ground truth {getattr(self, 'ground_truth_topic', None) or 'none'})")

    # ---- subclasses ----------------------------------------------------------------------------
    def _list_topics(self) -> dict[str, str]:
        raise NotImplementedError

    def _open_loader(self) -> None:
        raise NotImplementedError

    def _messages(self, topic: str) -> Iterator[tuple[int, Any]]:
        """``(index, deserialized message)`` of ``topic`` in order."""
        raise NotImplementedError

    # ---- ScanSequence ----------------------------------------------------------------------------
    def __len__(self) -> int:
        return self.n_scans

    @property
    def reader_options(self) -> dict[str, Any]:
        """The options as given and, once scans were read, ``time_field_used``: the field ``time_field`` resolved to
        (``auto`` alone did not say which of ``time`` and ``t`` a simulator bag's times came from; ``none``: no times)."""
        options = {"kind": self.kind, "path": str(self.path.absolute()), "topic": self.topic,
                   "ground_truth_topic": self.ground_truth_topic, "time_field": self.time_field}
        if self._time_fields_read:
            options["time_field_used"] = ", ".join(sorted(self._time_fields_read))
        return options

    @property
    def cloud_fields(self) -> tuple[str, ...] | None:
        """The field names of the clouds (the first one decoded; None before), for saying which ``time_field=`` can name."""
        return tuple(self._cloud_field_types) or None

    def _location(self, index: int) -> str:
        return f"message {index} on {self.topic}"

    #: what gave :attr:`n_scans`, the count of the topic's messages (said when the stream disagrees)
    _counted_by = "the bag's index"

    def _miscounted(self, n_read: int) -> DataError:
        """The error for a topic holding ``n_read`` messages where :attr:`n_scans` were counted: fewer (a truncated bag),
        or more (a ROS 2 bag's metadata.yaml under-counting them: only the counted ones would be read, without a word)."""
        if n_read < self.n_scans:
            return DataError(f"the bag ends after {n_read} of {self.n_scans} messages on {self.topic} ({self.n_scans}: the count "
                             f"in {self._counted_by}; truncated?)", source=self.path, location=self._location(n_read))
        return DataError(f"the bag holds {n_read} messages on {self.topic} but {self._counted_by} counts {self.n_scans}; only "
                         f"the counted ones would be read{self._recount_hint}", source=self.path)

    #: how to correct :attr:`_counted_by` when it under-counts
    _recount_hint = ""

    def _warn_once(self, key: str, message: str) -> None:
        """Keep ``message`` in :attr:`reader_warnings` and log it, the first time only (every message may have it)."""
        if key not in self._warned:
            self._warned.add(key)
            self.reader_warnings.append(message)
            log.warning("%s: %s", self.path, message)

    def _read_all(self, topic: str) -> Iterator[tuple[int, Any]]:
        """:meth:`_messages` of ``topic`` with a damaged file's reader failure as a DataError naming the message (the
        passes for the stamps and the ground truth read the whole topic, as :meth:`read_scan` reads up to a scan)."""
        stream = self._messages(topic)
        k = 0
        while True:
            try:
                item = next(stream)
            except StopIteration:
                return
            except DataError:
                raise
            except Exception as err:  # noqa: BLE001 - any reader or decoder failure of a damaged file becomes a DataError
                raise DataError(f"cannot read the message ({type(err).__name__}: {err}); truncated or damaged file?",
                                source=self.path, location=f"message {k} on {topic}") from None
            yield item
            k += 1

    def read_scan(self, index: int) -> Scan:
        """Scan ``index`` (messages are read in order; an earlier index restarts the stream)."""
        index = checked_index(index, self.n_scans, f"{self.path} ({self.topic})", from_end=False)
        decoded = self._decoded(index)
        stamp = self._stamps[index]
        instant = None
        if decoded.point_times_s is not None and len(decoded.point_times_s):
            t = decoded.point_times_s - (stamp if decoded.point_time_convention == "absolute_s" else 0.0)
            lo, hi = float(t.min()), float(t.max())
            if hi > lo:
                instant = classify_instant(-lo / (hi - lo))
        return Scan(decoded.points_xyz, decoded.intensity, decoded.point_times_s, stamp, index,
                    f"{self.path} {self._location(index)}", decoded.point_time_convention, instant)

    def _decoded(self, index: int, all_missing_ok: bool = False, first_pass: bool = False) -> DecodedCloud:
        """Message ``index`` decoded (read in order; an earlier index restarts the stream), what it leaves out said once;
        ``all_missing_ok``: a message of missing returns only decodes to no points (the sweep timing passes over it). Its
        point times are read in the bag's convention (:attr:`_point_time_convention`); ``first_pass`` (the pass over the
        first scans that decides it): in the one the message's own stamp gives, and nothing said (the scans read say it)."""
        convention = None if first_pass else self._point_time_convention
        if self._stream is None or index < self._next:
            self._stream = self._read_all(self.topic)
            self._next = 0
            self._last_stamp = None
        msg = None
        while self._next <= index:
            try:
                k, msg = next(self._stream)
            except StopIteration:
                raise self._miscounted(self._next) from None
            self._next += 1
            stamp = stamp_seconds(msg.header.stamp)
            if self._last_stamp is not None and stamp < self._last_stamp[1]:
                self._stream = None  # (as for the frame below: a pass that stopped here left the next read past it)
                raise DataError(
                    f"time goes backwards: header stamp {stamp:.9f} s is before {self._last_stamp[1]:.9f} s of message {self._last_stamp[0]}",
                    source=self.path, location=self._location(k),
                )
            self._last_stamp = (k, stamp)
            self._stamps[k] = stamp
            try:
                self._check_cloud_frame(k, msg)
            except DataError:  # (read again from the start: a pass that stopped here left the next read past the message)
                self._stream = None
                raise
        decoded = decode_pointcloud2(msg, source=str(self.path), location=self._location(index), time_field=self.time_field,
                                     all_missing_ok=all_missing_ok, convention=convention,
                                     convention_from=f"the first scans on {self.topic}")
        self._time_fields_read.add(decoded.time_field or "none")
        if not self._cloud_field_types:
            self._cloud_field_types = {str(f.name): int(f.datatype) for f in msg.fields}
        if not len(decoded.points_xyz) or first_pass:  # (said by the run when it reads the frame; --frames may leave it out)
            return decoded
        if decoded.n_at_origin:
            self._warn_once("origin", f"left out {decoded.n_at_origin} of {int(msg.width) * int(msg.height)} points at (0, 0, 0) "
                                      f"(missing returns) in {self._location(index)}; in later messages without another warning")
        if decoded.flat_time_fields:
            flat = ", ".join(repr(f) for f in decoded.flat_time_fields)
            self._warn_once("flat_time", f"per-point time field {flat} holds one value for every point of {self._location(index)}: "
                                         f"the times are read from {decoded.time_field!r} (time_field= names the field to read)")
        return decoded

    def _check_cloud_frame(self, k: int, msg: Any) -> None:
        """Keep message 0's ``header.frame_id`` as the clouds' frame; DataError for a later message in another frame: two
        sensors on one topic (a front and a rear LiDAR alternating on /points were registered as one sensor's sweeps,
        a 60.65 m path for a 3 m drive, without a word). A leading "/" (ROS 1's global names) is no other frame."""
        frame = str(msg.header.frame_id)
        if k == 0 or self._cloud_frame is None:
            self._cloud_frame = frame
        elif frame.lstrip("/") != self._cloud_frame.lstrip("/"):
            raise DataError(f"header.frame_id {frame!r} where message 0 on {self.topic} is in {self._cloud_frame!r}: the "
                            f"recording mixes sensors on one topic, and the reader reads one sensor per topic (it has no "
                            f"option to pick a frame: a bag with each sensor on its own topic reads with topic=...)",
                            source=self.path, location=self._location(k))

    @property
    def timestamps_s(self) -> np.ndarray:
        """Header stamps of every scan. The first call reads the whole topic: it holds :attr:`n_scans` messages (a
        ROS 2 bag's count comes from metadata.yaml, which may be wrong) whose stamps do not go back and are set."""
        if not self._stamps_checked:
            last = None
            n_read = 0
            for k, msg in self._read_all(self.topic):
                n_read = k + 1
                if k >= self.n_scans:  # (counted only)
                    continue
                stamp = stamp_seconds(msg.header.stamp)
                if last is not None and stamp < last:
                    raise DataError(f"time goes backwards: header stamp {stamp:.9f} s is before {last:.9f} s",
                                    source=self.path, location=self._location(k))
                last = stamp
                self._stamps[k] = stamp
                self._check_cloud_frame(k, msg)
            if n_read != self.n_scans:
                raise self._miscounted(n_read)
            if self.n_scans > 1 and not any(self._stamps.values()):  # (read "0 s after 0 s of frame 0: not increasing")
                raise DataError(f"every PointCloud2 header stamp on {self.topic} is 0 (not set by the driver): the scans have no "
                                "time stamps to order them, pair them with ground truth and write their poses by, and the "
                                "reader takes no other (a bag rewritten with the receive times as header stamps reads)",
                                source=self.path)
            self._stamps_checked = True
        return np.array([self._stamps[k] for k in range(self.n_scans)], dtype=np.float64)

    @property
    def ground_truth(self) -> Trajectory | None:
        """One recorded odometry pose per scan, ``meta["pose_instant"]`` read from the stamps (None if unclear)."""
        return self.ground_truth_of(None)

    def ground_truth_of(self, scans: np.ndarray | list[int] | None) -> Trajectory | None:
        """:attr:`ground_truth` of the scans numbered ``scans`` only (None: all): the same poses (and instant) the
        whole recording pairs with them; a recording whose odometry covers part of its scans is scored on that part
        (``--frames``; the whole recording's pairing refused the run)."""
        if self.ground_truth_topic is None:
            return None
        gt_stamps, gt_poses = self._recorded_ground_truth
        all_stamps = self.timestamps_s
        source = f"{self.path}{self.ground_truth_topic}"
        numbers = np.arange(self.n_scans) if scans is None else checked_indices(scans, self.n_scans, source, from_end=False)
        scan_stamps = all_stamps[numbers]
        period = float(np.median(np.diff(all_stamps))) if len(all_stamps) > 1 else 0.0
        # one pose per scan, each as far from its scan as the others: paired by count, whichever scans are selected (a
        # pose missing and one more after the last scan paired scans 7-14 of 15 with the next sweep's pose, 0.3-0.8 m off)
        if len(gt_stamps) == self.n_scans and np.ptp(gt_stamps - all_stamps) <= COUNT_PAIRING_SPREAD * period:
            gt_stamps, gt_poses = gt_stamps[numbers], gt_poses[numbers]
        else:
            if len(gt_stamps) < 2:
                raise DataError(f"{len(gt_stamps)} pose(s) for {len(scan_stamps)} scans: one pose per scan needed (--frames can pick the scans it covers; ground_truth_topic=none runs without scores)", source=source)
            # each scan's pose is the one nearest the place in the sweep where the poses are stamped (a pose stamped
            # mid-sweep lies as near the next scan's stamp as its own); a pose stamped with a scan is the end of the
            # sweep before only where each sweep ends as the next starts (taken so without point times)
            timing = self._sweep_timing
            following = timing is None or timing[1] == period  # (sweep_length gives the stamps' spacing itself then)
            # placed from where the sweeps start where the point times say (stamps lagging their sweeps by more than a
            # period put the phase, taken modulo the period, a sweep or two off), else from the stamps
            anchors = all_stamps + (timing[0] - all_stamps[0] if timing is not None and timing[1] > 0 else 0.0)
            target = anchors[numbers] + _pose_phase(gt_stamps, anchors, following)
            pick = np.clip(np.searchsorted(gt_stamps, target), 1, len(gt_stamps) - 1)
            pick = np.where(np.abs(gt_stamps[pick - 1] - target) <= np.abs(gt_stamps[pick] - target), pick - 1, pick)
            twice = np.flatnonzero(np.diff(pick) == 0)
            if len(twice):  # fewer (or sparser) poses than scans: one pose would stand for two scans
                k = int(twice[0])
                a, b = int(numbers[k]), int(numbers[k + 1])
                where = (f"scan {a} ({scan_stamps[k]:.3f} s) comes before the first pose ({gt_stamps[0]:.3f} s)"
                         if target[k + 1] <= gt_stamps[0] else
                         f"scan {b} ({scan_stamps[k + 1]:.3f} s) comes after the last pose ({gt_stamps[-1]:.3f} s)"
                         if target[k] >= gt_stamps[-1] else
                         f"scans {a} and {b} are both nearest to the pose at {gt_stamps[pick[k]]:.3f} s")
                raise DataError(f"{len(gt_stamps)} poses for {len(scan_stamps)} scans: {where}; one pose per scan needed (--frames can pick the scans it covers; ground_truth_topic=none runs without scores)", source=source)
            gt_stamps, gt_poses = gt_stamps[pick], gt_poses[pick]
        self._check_poses_near_their_sweeps(gt_stamps, scan_stamps, numbers, period, source)
        meta = {"frame": f"as recorded on {self.ground_truth_topic}", "pose_instant": self._ground_truth_instant(gt_stamps, scan_stamps)}
        return Trajectory(gt_poses, gt_stamps, name=f"{self.path.name}{self.ground_truth_topic}", meta=meta)

    def _check_poses_near_their_sweeps(self, gt_stamps: np.ndarray, scan_stamps: np.ndarray, numbers: np.ndarray, period: float,
                                       source: str) -> None:
        """DataError when a pose paired with a scan (``gt_stamps[j]`` with scan ``numbers[j]``, stamped ``scan_stamps[j]``)
        is not that scan's time: more than a sweep outside the sweep where the point times place it, or, without them,
        more than 1.5 periods from the scan's stamp. (Stamps lagging their sweeps by a driver's 150 ms latency refused
        the odometry stamped at the sweep ends, paired one each by count, as "0.150 s apart, more than a sweep".)"""
        if not period > 0:
            return
        timing = self._sweep_timing
        apart = np.abs(gt_stamps - scan_stamps)
        if timing is None or not timing[1] > 0:  # one pose per scan by count, but not the scan's own time
            far, where = apart > 1.5 * period, ""
        else:
            starts = scan_stamps + (timing[0] - float(self.timestamps_s[0]))
            ends = starts + timing[1]
            far = np.maximum(starts - gt_stamps, gt_stamps - ends) > period
            where = " outside the scan's sweep ({:.3f}-{:.3f} s by its point times)"
        if far.any():
            k = int(np.flatnonzero(far)[0])
            where = where.format(starts[k], ends[k]) if where else ""
            raise DataError(f"pose {k} is stamped {gt_stamps[k]:.3f} s, scan {int(numbers[k])} {scan_stamps[k]:.3f} s: {apart[k]:.3f} s "
                            f"apart, more than a sweep ({period:.3f} s){where}; {NOT_COVERED}", source=source)

    def ground_truth_at_instant(self, instant: str, scans: np.ndarray | list[int] | None = None) -> Trajectory:
        """The ground truth at the ``instant`` (start, mid or end) of every sweep (``scans``: of those only, e.g. a
        ``--frames`` selection within what the recording covers). A recording that keeps the poses at that instant
        (:func:`sweep_instant_topic`, e.g. ``/ground_truth/sweep_mid``, as the simulator's bags do) gives them as
        recorded (the one nearest each instant, within :data:`KEPT_INSTANT_SHARE` of a sweep); otherwise the recorded
        odometry is interpolated (rotation slerped, position linear in time: off by about ``a dt^2 / 8`` where the
        motion accelerates by ``a`` between poses ``dt`` apart, a size the note gives from the poses' second
        differences), or continued at constant velocity for at most 1.5 recording intervals beyond
        the first or last pose (e.g. the start of sweep 0 when the poses are stamped at sweep ends). The instants are
        placed by the first scans' point times (where a sweep starts, how long it lasts: :attr:`sweep_duration_s`) and
        the scans' stamps; DataError when the scans carry no point times (or times on another clock than their stamps)
        or the recording does not reach."""
        if instant not in INSTANT_FRACTION:
            raise DataError(f"unknown instant {instant!r}; valid: {', '.join(INSTANT_FRACTION)}", source=self.path)
        if self.ground_truth_topic is None:
            raise DataError("no ground-truth topic", source=self.path)
        timing = self._sweep_timing
        if timing is None:
            raise DataError(self._timing_problem or "the scans carry no per-point times, so where a sweep starts and ends is unknown",
                            source=self.path, location=self._location(0))
        start, sweep_s = timing
        all_stamps = self.timestamps_s
        scan_stamps = all_stamps if scans is None else all_stamps[np.asarray(scans, dtype=np.int64)]
        times = scan_stamps + (start - all_stamps[0]) + INSTANT_FRACTION[instant] * sweep_s
        kept_topic = sweep_instant_topic(self.ground_truth_topic, instant)
        kept = self._topics.get(kept_topic) == POSE_STAMPED
        topic = kept_topic if kept else self.ground_truth_topic
        stamps, poses = self._poses_at_instant(kept_topic) if kept else self._recorded_ground_truth
        name = f"{self.path.name}{self.ground_truth_topic}"
        meta = {"frame": f"as recorded on {self.ground_truth_topic}", "pose_instant": instant}
        if kept and len(stamps):  # the pose recorded at each instant, as stamped (to the stamps' nanoseconds): exact
            after = np.clip(np.searchsorted(stamps, times), 0, len(stamps) - 1)
            before = np.maximum(after - 1, 0)
            nearest = np.where(np.abs(stamps[before] - times) <= np.abs(stamps[after] - times), before, after)
            # or, a little off, the pose kept for that very instant: the sweep's length from the points' span falls
            # short of the period (a one-sweep recording: 0.098 s for 0.1, whose single pose cannot be interpolated)
            if np.all(np.abs(stamps[nearest] - times) <= max(KEPT_INSTANT_SHARE * sweep_s, 2e-9)):
                meta["retimed"] = f"the poses recorded at the sweep {instant} on {topic}"
                return Trajectory(poses[nearest], times, name=name, meta=meta)
        if len(stamps) < 2 or not (np.diff(stamps) > 0).all():
            raise DataError(f"{topic}: interpolating needs two or more poses with increasing stamps", source=self.path)
        recorded = Trajectory(poses, stamps, name=name)
        reach = 1.5 * float(np.median(np.diff(stamps)))
        out = recorded.interpolated(times, max_extrapolation_s=reach)
        # (an instant equal to a recorded stamp but for rounding, 1e-16 s beyond it, was counted as continued)
        tolerance = 1e-6 * (sweep_s if sweep_s > 0 else float(np.median(np.diff(stamps))))
        n_out = int(((times < stamps[0] - tolerance) | (times > stamps[-1] + tolerance)).sum())
        how = f"interpolated between the {len(stamps)} poses recorded on {topic}"
        if n_out:
            how += f", {n_out} frame(s) continued at constant velocity beyond them"
        error_m = interpolation_error_m(stamps, poses[:, :3, 3], times)
        if error_m > EXACT_RETIMING_M:  # (the mid-sweep truth of a pulling-away drive was up to 9 mm off, unsaid)
            size = f"{error_m * 1e3:.2g} mm" if error_m < 0.1 else f"{error_m:.2g} m"
            how += (f"; linear in time between them, the position may be up to about {size} off where the recorded motion "
                    "accelerates (estimated from their second differences)")
        meta["retimed"] = how
        return Trajectory(out.poses_se3, times, name=name, meta=meta)

    def _poses_at_instant(self, topic: str) -> tuple[np.ndarray, np.ndarray]:
        """Stamps (s) and poses ``(n, 4, 4)`` of the ``geometry_msgs/PoseStamped`` messages on ``topic`` (the poses at
        one instant of every sweep: :func:`sweep_instant_topic`) in header-stamp order, read once."""
        if topic not in self._instant_poses:
            stamps, poses = [], []
            for k, (_, msg) in enumerate(self._read_all(topic)):
                stamps.append(stamp_seconds(msg.header.stamp))
                poses.append(_checked_pose(msg.pose, f"{self.path}{topic}", k))
            order = np.argsort(stamps, kind="stable")
            self._instant_poses[topic] = (np.array(stamps)[order], np.stack(poses)[order] if poses else np.zeros((0, 4, 4)))
        return self._instant_poses[topic]

    @cached_property
    def _recorded_ground_truth(self) -> tuple[np.ndarray, np.ndarray]:
        """Stamps (s) and poses ``(n, 4, 4)`` of every message on the ground-truth topic in header-stamp order, exact
        repeats (same stamp and pose) once (read once: the ground truth and its re-timing both use them). One message
        logged out of order stopped the re-timing: it needs increasing stamps."""
        stamps, poses, child_frames = [], [], set()
        for k, (_, msg) in enumerate(self._read_all(self.ground_truth_topic)):
            child_frames.add(str(msg.child_frame_id))
            stamps.append(stamp_seconds(msg.header.stamp))
            poses.append(_checked_pose(msg.pose.pose, f"{self.path}{self.ground_truth_topic}", k))
        if not poses:
            raise DataError(f"ground-truth topic {self.ground_truth_topic} has no messages (ground_truth_topic=none runs without "
                            "ground truth)", source=self.path)
        self._check_ground_truth_frame(child_frames)
        stamps, poses = np.array(stamps), np.stack(poses)
        if len(stamps) > 1 and not stamps.any():  # (read "12 poses for 12 scans ... one pose per scan needed")
            raise DataError(f"every header stamp on the ground-truth topic {self.ground_truth_topic} is 0 (not set by the "
                            "driver): its poses cannot be paired with the scans (ground_truth_topic=none runs without ground "
                            "truth)", source=self.path)
        n_back = int(np.count_nonzero(np.diff(stamps) < 0))
        if n_back:
            order = np.argsort(stamps, kind="stable")
            stamps, poses = stamps[order], poses[order]
        repeated = np.flatnonzero((np.diff(stamps) == 0) & (poses[1:] == poses[:-1]).all(axis=(1, 2))) + 1
        if len(repeated):
            stamps, poses = np.delete(stamps, repeated), np.delete(poses, repeated, axis=0)
        if n_back or len(repeated):
            said = [f"{n_back} logged before an earlier stamp: read in header-stamp order"] if n_back else []
            said += [f"{len(repeated)} repeating the message before (same stamp and pose): read once"] if len(repeated) else []
            self._warn_once("ground_truth_order", f"ground-truth topic {self.ground_truth_topic}: of {len(stamps) + len(repeated)} "
                                                  f"poses, {' and '.join(said)}")
        return stamps, poses

    def _check_ground_truth_frame(self, child_frames: set[str]) -> None:
        """Warn when the odometry is the pose of another frame than the clouds' (``child_frame_id`` against the clouds'
        ``header.frame_id``): a base_link pose scored as the LiDAR's counts the offset between the two as error."""
        if self._cloud_frame is None:
            with contextlib.closing(self._read_all(self.topic)) as clouds:  # (the first message only; an open cursor locks sqlite3)
                for _, msg in clouds:
                    self._cloud_frame = str(msg.header.frame_id)
                    break
        cloud = (self._cloud_frame or "").lstrip("/")
        others = sorted(f for f in child_frames if f.lstrip("/") and f.lstrip("/") != cloud)
        if cloud and others:
            named = ", ".join(repr(f) for f in others)
            self._warn_once("ground_truth_frame", f"ground-truth topic {self.ground_truth_topic} gives the pose of frame {named} "
                                                  f"(child_frame_id), the clouds on {self.topic} are in frame {self._cloud_frame!r}: "
                                                  "the ground truth is not the LiDAR's pose and is compared as if it were (the "
                                                  "offset between the two frames counts as error)")

    def _ground_truth_instant(self, gt_stamps: np.ndarray, scan_stamps: np.ndarray) -> str | None:
        """Which instant of its scan's sweep each pose is stamped at (``gt_stamps[j]`` paired with the scan stamped
        ``scan_stamps[j]``; the median over the pairs), None when the scans carry no point times or it is no instant."""
        timing = self._sweep_timing
        if timing is None:
            return None
        start, sweep_s = timing
        if sweep_s <= 0:  # the scans' stamps are all equal: no sweep period to place the poses in
            return None
        sweep_start = scan_stamps + (start - float(self.timestamps_s[0]))  # a sweep starts as far from its stamp as sweep 0
        return classify_instant(float(np.median((gt_stamps - sweep_start) / sweep_s)))

    @property
    def stamp_instant(self) -> str | None:
        """Where in its sweep a scan is stamped (start, mid, end), from the first scans' point times (their median: a
        first message holding part of a sweep does not decide it); None without point times or a clear instant."""
        timing = self._sweep_timing
        if timing is None or not timing[1] > 0:
            return None
        return classify_instant((float(self.timestamps_s[0]) - timing[0]) / timing[1])

    @property
    def sweep_offset_s(self) -> float | None:
        """Seconds from a scan's header stamp to the start of its sweep (negative: the sweep starts before it), from the
        first scans' point times; None without point times on the stamps' clock. It places each sweep where its stamp is
        at no clear instant (a driver stamping on receipt, 30 ms after the sweep end, had its poses written 30-80 ms off)."""
        timing = self._sweep_timing
        return None if timing is None or not timing[1] > 0 else timing[0] - float(self.timestamps_s[0])

    @property
    def sweep_duration_s(self) -> float | None:
        """How long a sweep lasts, from its first point to the next sweep's (the stamps' spacing; one firing step past
        its last point for a recording of one sweep) or, when the points span clearly less or more than that spacing,
        to its last point; None without point times on the stamps' clock."""
        timing = self._sweep_timing
        return None if timing is None or not timing[1] > 0 else timing[1]

    @cached_property
    def _sweep_timing(self) -> tuple[float, float] | None:
        """(absolute time sweep 0 starts, how long a sweep lasts) from the point times of the first
        :data:`SWEEP_TIMING_SCANS` scans that carry them (where a sweep's first point fires after its stamp and how long
        its points span: medians, so that a recording begun mid-rotation, whose first message holds part of a sweep,
        does not place every sweep by that part; a driver's empty start-up cloud is passed over: it made the whole
        recording one without point times) and the spacing of the stamps (:func:`sweep_length`, given the step between
        firings: a recording keeping every other sweep, or a sensor seeing part of its turn, lasts from first to last
        point, not the stamps' spacing; a recording of one sweep, to one step past its last point); 0 for the length
        when the stamps are all equal; None when none of the first
        :data:`SWEEP_TIMING_READ` scans carries point times, or they carry times on another clock than the stamps (a
        sweep more than :data:`CLOCK_GAP_S` and :data:`CLOCK_GAP_PERIODS` periods from its stamp, beyond a driver's
        latency: :attr:`reader_warnings` says so, with the field and the offset).
        DataError when the sweeps span less than :data:`~lidarkit.io.pointcloud2.MIN_SWEEP_SHARE` of the stamps'
        spacing and under :data:`~lidarkit.io.pointcloud2.MIN_SWEEP_S`: times in microseconds read as nanoseconds.
        A bag keeping the poses at every sweep's start and end gives the timing by their stamps where it disagrees with
        the points' (:meth:`_kept_sweep_timing`)."""
        offsets, ends, spans, steps = [], [], [], []
        for stamp, times in self._first_sweeps:
            t = times + (0.0 if self._point_time_convention == "absolute_s" else stamp)
            lo, hi = float(t.min()), float(t.max())
            offsets.append(lo - stamp)
            ends.append(hi - stamp)
            spans.append(hi - lo)
            steps.append((hi - lo) / (len(np.unique(t)) - 1))  # between firings (columns sharing a time: few)
        if not offsets:
            return None
        stamps = self.timestamps_s
        # one sweep alone: from its first point to one firing step past its last (where the next sweep would start)
        period = float(np.median(np.diff(stamps))) if len(stamps) > 1 else max(spans) + steps[int(np.argmax(spans))]
        # a sweep lies around its stamp (from it, up to it, or across it, or up to a driver's latency from it: stamped
        # on receipt, 120-150 ms after the sweep end, which read as another clock); one further away is timed by another
        # clock (GPS time against UTC stamps, seconds since the sensor booted): its instant cannot be placed
        first, last = float(np.median(offsets)), float(np.median(ends))
        apart = first if first > 0 else last if last < 0 else 0.0
        if abs(apart) > max(CLOCK_GAP_S, CLOCK_GAP_PERIODS * period, max(spans)):
            fields = ", ".join(repr(f) for f in sorted(self._time_fields_read))
            self._timing_problem = (f"the point times (field {fields}) lie {abs(apart):.6g} s {'after' if apart > 0 else 'before'} "
                                    f"the header stamps (a median over the first scans; the stamps are {period:.4g} s apart): "
                                    "another clock? where each sweep lies against the stamps cannot be placed")
            self._warn_once("clock", f"{self._timing_problem}: the sweep instant of the scans and of the ground truth is unknown")
            return None
        span = float(np.median(spans))
        if len(stamps) > 1:  # (microseconds read as nanoseconds: sweeps of 1e-4 s placed the ground truth by them)
            named = sorted(self._time_fields_read - {"none"})
            codes = {self._cloud_field_types.get(f) for f in named} - {None}
            unit = time_unit_read(np.dtype(POINTFIELD_DTYPES[codes.pop()])) if len(codes) == 1 else "nanoseconds or seconds"
            check_sweep_span(span, period, what=f"per-point time field {', '.join(repr(f) for f in named)}", unit=unit,
                             over=f"the median over the first {len(spans)} scans", source=self.path,
                             hint="time_field=none reads the scans without point times")
        timing = float(stamps[0] + first), sweep_length(span, period, float(np.median(steps)))
        kept = self._kept_sweep_timing(period)
        # (the kept instants, stamped to the nanosecond, where they disagree with the points: else as the points say)
        return kept if kept is not None and max(abs(kept[0] - timing[0]), abs(kept[1] - timing[1])) > 1e-6 else timing

    @cached_property
    def _first_sweeps(self) -> list[tuple[float, np.ndarray]]:
        """(stamp, point times as stored) of the first :data:`SWEEP_TIMING_SCANS` scans whose times span a sweep, of the
        first :data:`SWEEP_TIMING_READ` (a driver's empty start-up cloud is passed over); none when the clouds have no
        time field; those before a message that cannot be read. The bag's point-time convention and its sweep timing are
        read from them."""
        sweeps: list[tuple[float, np.ndarray]] = []
        for k in range(min(self.n_scans, SWEEP_TIMING_READ)):
            try:
                decoded = self._decoded(k, all_missing_ok=True, first_pass=True)
            except DataError:  # (said when that scan is read: reading scan 0 refused message 1, which --frames left out)
                break
            if decoded.time_field is None and len(decoded.points_xyz):  # clouds without a time field: none will have one
                break
            times = decoded.point_times_s
            if times is None or len(times) < 2 or not np.ptp(times) > 0:
                continue
            sweeps.append((self._stamps[k], times))
            if len(sweeps) == SWEEP_TIMING_SCANS:
                break
        return sweeps

    @cached_property
    def _point_time_convention(self) -> str | None:
        """The one convention of the bag's per-point times (:func:`~lidarkit.io.pointcloud2.recording_time_convention` of
        :attr:`_first_sweeps`), None when they carry none (each message is then read by its own). Per message, the first
        scans of a simulator's clock starting at 0 read their absolute times as relative, 0.1-0.2 s off."""
        sweeps = self._first_sweeps
        if not sweeps:
            return None
        return recording_time_convention(np.array([stamp for stamp, _ in sweeps]), np.array([t.min() for _, t in sweeps]),
                                         np.array([t.max() for _, t in sweeps]))

    def _kept_sweep_timing(self, period: float) -> tuple[float, float] | None:
        """(absolute time sweep 0 starts, how long a sweep lasts) from the poses the recording keeps at every sweep's
        start and end (:func:`sweep_instant_topic`, stamped at those instants, as the simulator's bags do): the
        medians over the first :data:`SWEEP_TIMING_SCANS` scans of their start's offset from the stamp and their
        end minus start. A sensor seeing part of its turn has points spanning less than its sweep (0.088 s of 0.1):
        timed by them, a bag placed its truth up to 64 mm off where the same sweeps as a KITTI folder were scored from
        the sweep itself. None without both topics, or when a kept start is not within a stamp period of its scan."""
        if not self.ground_truth_topic or not period > 0:
            return None
        topics = [sweep_instant_topic(self.ground_truth_topic, instant) for instant in ("start", "end")]
        if any(self._topics.get(topic) != POSE_STAMPED for topic in topics):
            return None
        start_stamps, end_stamps = (self._poses_at_instant(topic)[0] for topic in topics)
        if not len(start_stamps) or not len(end_stamps):
            return None
        stamps = self.timestamps_s[:SWEEP_TIMING_SCANS]
        after = np.clip(np.searchsorted(start_stamps, stamps), 0, len(start_stamps) - 1)
        before = np.maximum(after - 1, 0)
        starts = start_stamps[np.where(np.abs(start_stamps[before] - stamps) <= np.abs(start_stamps[after] - stamps), before, after)]
        after = np.searchsorted(end_stamps, starts, side="right")
        if np.any(np.abs(starts - stamps) > period) or np.any(after >= len(end_stamps)):
            return None
        lengths = end_stamps[after] - starts
        if not np.all((lengths > 0) & (lengths <= 1.5 * period)):
            return None
        return float(self.timestamps_s[0] + np.median(starts - stamps)), float(np.median(lengths))


#: least gap (s) between the header stamps and their sweeps' point times read as another clock (a driver's latency,
#: stamping a sweep on receipt, is less), unless :data:`CLOCK_GAP_PERIODS` stamp periods are more
CLOCK_GAP_S = 1.0
#: least gap, in stamp periods, between the header stamps and their sweeps read as another clock
CLOCK_GAP_PERIODS = 3
#: what a refused pairing of the odometry with the scans can do instead
NOT_COVERED = ("the odometry does not cover the scans one pose each (--frames can pick the scans it covers; "
               "ground_truth_topic=none runs without scores)")
#: scans whose point times place the sweeps in the stamps (the median over them)
SWEEP_TIMING_SCANS = 5
#: most scans read to find :data:`SWEEP_TIMING_SCANS` with point times (empty or timeless ones are passed over)
SWEEP_TIMING_READ = 3 * SWEEP_TIMING_SCANS
#: most spread of the pose-minus-scan stamp offsets, in scan periods, for one pose per scan to be paired by count
COUNT_PAIRING_SPREAD = 0.25
#: how far (a share of the sweep) an instant may be from a pose recorded on its sweep_<instant> topic to be given it
KEPT_INSTANT_SHARE = 0.05
#: most scan periods between one part of a split ROS 1 recording and the next (further apart: separate recordings)
SPLIT_GAP_PERIODS = 3
#: most time (s) a part of a split ROS 1 recording may begin before the one before ends (messages of one instant)
SPLIT_OVERLAP_S = 1e-3


def _pose_phase(gt_stamps: np.ndarray, scan_stamps: np.ndarray, following: bool = True) -> float:
    """Where in the scan period the poses are stamped (s after a scan's stamp, in ``[0, period)``), when they keep one
    place (one pose per sweep, stamped at its start, middle or end); 0 when they do not (odometry at its own rate).
    ``following``: each sweep ends where the next starts (else a pose stamped with a scan is its own sweep's, not the
    one before's: a recording keeping every other sweep)."""
    if len(scan_stamps) < 2:
        return 0.0
    period = float(np.median(np.diff(scan_stamps)))
    if not period > 0:
        return 0.0
    mean = np.exp(2j * np.pi * (gt_stamps - scan_stamps[0]) / period).mean()
    if abs(mean) < 0.8:  # spread over the period: not one pose per sweep at one instant
        return 0.0
    phase = float(np.angle(mean) / (2 * np.pi) % 1.0)
    # poses stamped with the scans (the end of one sweep is the start of the next, the same instant): read as each
    # sweep's end, whichever side of the period rounding put them, so that the first scan keeps its pose
    return period if following and min(phase, 1.0 - phase) < 0.02 else phase * period


#: most position error (m) of re-timed ground truth left unsaid: instants on the recorded poses' stamps (or as good)
EXACT_RETIMING_M = 1e-6


def interpolation_error_m(stamps_s: np.ndarray, positions_m: np.ndarray, times_s: np.ndarray) -> float:
    """About how far (m) positions linear in time between the poses at ``stamps_s`` ``(n,)`` (``positions_m`` ``(n, 3)``),
    continued at constant velocity beyond them, lie from the path at ``times_s`` at most: half the acceleration, from
    the poses' second differences (the larger at either end of an interval), times ``|t - t_i| |t - t_i+1|`` for the
    interval ``i, i+1`` used (``a dt^2 / 8`` mid-way); 0 for fewer than three poses, where no acceleration is known."""
    if len(stamps_s) < 3 or not len(times_s):
        return 0.0
    velocity = np.diff(positions_m, axis=0) / np.diff(stamps_s)[:, None]
    accel = np.linalg.norm(2.0 * np.diff(velocity, axis=0) / (stamps_s[2:] - stamps_s[:-2])[:, None], axis=1)
    at_stamp = np.concatenate([accel[:1], accel, accel[-1:]])  # the ends take their neighbour's
    i = np.clip(np.searchsorted(stamps_s, times_s, side="right") - 1, 0, len(stamps_s) - 2)
    spread = np.abs((times_s - stamps_s[i]) * (times_s - stamps_s[i + 1]))
    return float(np.max(0.5 * np.maximum(at_stamp[i], at_stamp[i + 1]) * spread))


def _checked_pose(pose: Any, source: str, k: int) -> np.ndarray:
    """The 4x4 of a ``geometry_msgs/Pose`` (message ``k`` of ``source``); DataError for a non-finite position or a
    quaternion that is not one."""
    p, q = pose.position, pose.orientation
    xyz, quat = [p.x, p.y, p.z], [q.x, q.y, q.z, q.w]
    if not np.isfinite(xyz + quat).all() or not np.linalg.norm(quat) > 1e-6:
        raise DataError(f"pose {xyz} with orientation {quat}: not a finite position and unit quaternion", source=source,
                        location=f"message {k}")
    return _pose_matrix(xyz, quat)


def _pose_matrix(xyz: list[float], quat_xyzw: list[float]) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(quat_xyzw).as_matrix()
    T[:3, 3] = xyz
    return T


def _starts_with(path: Path, head: bytes) -> bool:
    """Whether the file at ``path`` begins with ``head`` (False when it cannot be read: the reader then says why)."""
    try:
        with open(path, "rb") as fh:
            return fh.read(len(head)) == head
    except OSError:
        return False


def bag_path(path: str | os.PathLike) -> Path:
    """The path a bag is read from: a ROS 2 bag's ``metadata.yaml`` (a path copied from a file browser) stands for the
    bag, its folder, taken absolute (from inside the folder, "." named the run "rosbag:/points"); other paths as given."""
    given = Path(path)
    return given.absolute().parent if given.name == "metadata.yaml" and given.is_file() else given


class RosbagScans(_BagScans):
    """ROS 1 ``.bag`` (or a folder of split bags) or ROS 2 bag folder (or its ``metadata.yaml``), via kiss-icp's
    ``RosbagDataset``.

    Options: ``topic`` (the PointCloud2 topic; needed when there are several), ``ground_truth_topic`` (a
    ``nav_msgs/Odometry`` topic; default: the only one, ``""`` or ``none``: none), ``time_field`` (``auto``, a field name or
    ``none``); None (a spec's ``null``) is each option's default. The words ``none``, ``null`` and ``auto`` are read in
    any case; a topic named without its leading slash (``points``) is the bag's ``/points``.
    """

    kind = "rosbag"

    def __init__(self, path: str | os.PathLike, topic: str | None = None, ground_truth_topic: str | None = None,
                 time_field: str | None = "auto"):
        require_modules({"rosbags": ROS_EXTRA}, "rosbag")
        super().__init__(bag_path(path), topic, ground_truth_topic, time_field)

    @property
    def _counted_by(self) -> str:
        return "metadata.yaml" if (self.path / "metadata.yaml").is_file() else "the bag's index"

    @property
    def _recount_hint(self) -> str:
        return " ('ros2 bag reindex' rebuilds metadata.yaml from the storage)" if self._counted_by == "metadata.yaml" else ""

    def _reader_paths(self) -> list[Path]:
        if self.path.is_dir():
            split = sorted(self.path.glob("*.bag"))
            if split:
                return split
        return [self.path]

    def _list_topics(self) -> dict[str, str]:
        from rosbags.highlevel import AnyReader

        paths = self._reader_paths()
        if self.path.is_file() and self.path.suffix != ".bag" and _starts_with(self.path, ROS1_MAGIC):  # (rosbags: "unknown storage format")
            active = self.path.name.endswith(".bag.active")  # (what a killed `rosbag record` leaves, unindexed)
            name = self.path.name[: -len(".active")] if active else f"{self.path.stem if self.path.suffix.lower() == '.bag' else self.path.name}.bag"
            raise DataError(f"a ROS 1 bag, read only by a lower-case .bag name: {'run rosbag reindex on it, then ' if active else ''}"
                            f"rename it to {name}", source=self.path)
        try:
            with AnyReader(paths) as reader:
                topics = {t: info.msgtype for t, info in reader.topics.items()}
            if len(paths) > 1:
                spans = []  # (first, last receive time ns, scan messages) of each part
                for part in paths:
                    with AnyReader([part]) as reader:
                        scans = max((info.msgcount for info in reader.topics.values() if info.msgtype == POINTCLOUD2), default=0)
                        # (rosbags' end_time is exclusive: the last message's time + 1 ns)
                        spans.append((reader.start_time, reader.end_time - 1, scans) if reader.message_count else None)
        except Exception as err:  # noqa: BLE001 - rosbags raises its own error types for damaged files
            from lidarkit.io import ros2_storage_problem

            if paths != [self.path]:  # split parts: name the unreadable one (it said "no .bag files")
                for part in paths:
                    try:
                        with AnyReader([part]):
                            pass
                    except Exception as part_err:  # noqa: BLE001
                        raise DataError(f"not a readable ROS bag ({type(part_err).__name__}: {part_err}; truncated or "
                                        f"damaged?)", source=part) from None
            problem = ros2_storage_problem(self.path)
            if problem is None and paths == [self.path] and self.path.is_dir() and not (self.path / "metadata.yaml").exists():
                from lidarkit.io import detect_kind

                kind = detect_kind(self.path)  # (a KITTI folder was "a truncated or damaged bag")
                problem = ("a folder that is no ROS bag (no .bag files, no metadata.yaml)"
                           + (f": it reads as {kind!r} data ({kind}:PATH)" if kind and kind != "rosbag" else ""))
            raise DataError(problem or f"not a readable ROS bag ({type(err).__name__}: {err}; truncated or damaged?)",
                            source=self.path) from None
        if len(paths) > 1:
            self._check_split_parts(paths, spans)
        return topics

    def _check_split_parts(self, paths: list[Path], spans: list[tuple[int, int, int] | None]) -> None:
        """DataError unless the bags of the folder are parts of one recording, each beginning where the one before ends
        (within :data:`SPLIT_GAP_PERIODS` scan periods; ``spans``: each part's first and last message time, ns): two
        recordings were read as one, 24 frames with a 98.9 s gap (RPE 107 m), and two copies of one bag failed on
        stamps "not strictly increasing". A part may begin at the time the one before ends (messages logged at one
        instant split between them: up to :data:`SPLIT_OVERLAP_S`), which was refused as "begins 0.000 s before"."""
        parts = sorted((span[0], span[1], span[2], path) for path, span in zip(paths, spans) if span is not None)
        periods = [(end - start) / (n - 1) for start, end, n, _ in parts if n > 1]
        gap_ns = SPLIT_GAP_PERIODS * (float(np.median(periods)) if periods else 1e9 * MAX_SWEEP_S)
        for (_, end, _, before), (start, _, _, after) in zip(parts, parts[1:]):
            if end - start > 1e9 * SPLIT_OVERLAP_S or start - end > gap_ns:
                how = (f"{after.name} begins {1e-9 * (start - end):.3f} s after {before.name} ends" if start >= end else
                       f"{after.name} begins {1e-9 * (end - start):.3f} s before {before.name} ends")
                names = ", ".join(path.name for path in paths)
                raise DataError(f"{len(paths)} bags ({names}) that are no parts of one recording: {how} (a split recording's "
                                f"parts follow one another within {SPLIT_GAP_PERIODS} scan periods); read each on its own, "
                                f"e.g. rosbag:{self.path / paths[0].name}", source=self.path)

    def _open_loader(self) -> None:
        from kiss_icp.datasets.rosbag import RosbagDataset

        with guarded_loader("rosbag", str(self.path)):
            self.loader = RosbagDataset(self.path, topic=self.topic)
        self.n_scans = int(self.loader.n_scans)

    def _messages(self, topic: str) -> Iterator[tuple[int, Any]]:
        bag = self.loader.bag
        connections = [c for c in bag.connections if c.topic == topic]
        for k, (connection, _, raw) in enumerate(bag.messages(connections=connections)):
            try:
                msg = bag.deserialize(raw, connection.msgtype)
            except Exception as err:  # noqa: BLE001
                raise DataError(f"cannot decode the message ({type(err).__name__}: {err})", source=self.path,
                                location=f"message {k} on {topic}") from None
            yield k, msg

    def close(self) -> None:
        """Release the bag (kiss-icp's loader keeps an open message cursor; a cursor left open locks sqlite3)."""
        for stream in (getattr(self, "_stream", None), getattr(getattr(self, "loader", None), "msgs", None)):
            if stream is not None:
                with contextlib.suppress(Exception):
                    stream.close()
        self._stream = None
        bag = getattr(getattr(self, "loader", None), "bag", None)
        if bag is not None:
            with contextlib.suppress(Exception):
                bag.close()
            del self.loader.bag  # kiss-icp's __del__ closes it only when still there

    def __del__(self) -> None:
        self.close()


class McapScans(_BagScans):
    """A standalone ``.mcap`` file, via kiss-icp's ``McapDataloader`` (options as :class:`RosbagScans`); channels of
    ROS 1 messages (``ros1msg`` schemas, an MCAP converted from a ROS 1 bag) are decoded by rosbags, which kiss-icp's
    loader does not read."""

    kind = "mcap"
    _counted_by = "the file's summary"

    def __init__(self, path: str | os.PathLike, topic: str | None = None, ground_truth_topic: str | None = None,
                 time_field: str | None = "auto"):
        require_modules({"mcap": ROS_EXTRA, "mcap_ros2": ROS_EXTRA}, "mcap")
        if Path(path).is_dir():
            raise DataError("an MCAP dataset is one .mcap file; a ROS 2 bag folder is read with rosbag:PATH", source=path)
        super().__init__(path, topic, ground_truth_topic, time_field)

    def _summary(self):
        from mcap.reader import make_reader

        head = b""
        try:
            with open(self.path, "rb") as fh:
                head = fh.read(8)
                fh.seek(0)
                summary = make_reader(fh).get_summary()
        except Exception as err:  # noqa: BLE001 - mcap raises its own error types for damaged files
            if head == ROS1_MAGIC:  # (a ROS 1 bag was "invalid magic: (35, 82, 79, ...); truncated or damaged?")
                raise DataError(f"a ROS 1 bag, not an MCAP file: read it with rosbag:{self.path}", source=self.path) from None
            raise DataError(f"not a readable MCAP file ({type(err).__name__}: {err}; truncated or damaged?)", source=self.path) from None
        if summary is None:
            raise DataError("MCAP file has no summary section (truncated, or written without one)", source=self.path)
        return summary

    def _list_topics(self) -> dict[str, str]:
        summary = self._summary()
        topics = {}
        #: the ROS 2 type name and the schema of each topic whose messages are ROS 1 encoded
        self._ros1_schemas: dict[str, tuple[str, Any]] = {}
        for channel in summary.channels.values():
            schema = summary.schemas.get(channel.schema_id)
            name = schema.name if schema is not None else "no schema"
            if schema is not None and schema.encoding == "ros1msg" and channel.message_encoding == "ros1":
                name = _ros2_type_name(name)  # (sensor_msgs/PointCloud2 was "not sensor_msgs/msg/PointCloud2")
                self._ros1_schemas[channel.topic] = (name, schema)
            elif schema is not None and name == POINTCLOUD2 and schema.encoding != "ros2msg":
                name = f"{name} [{schema.encoding} schema, not ros2msg or ros1msg]"
            topics[channel.topic] = name
        return topics

    def _open_loader(self) -> None:
        if self.topic in self._ros1_schemas:  # (kiss-icp's loader reads ROS 2 messages only)
            self.loader = None
            summary = self._summary()
            counts = summary.statistics.channel_message_counts if summary.statistics is not None else None
            self.n_scans = (sum(n for c, n in counts.items() if summary.channels[c].topic == self.topic) if counts is not None
                            else sum(1 for _ in self._mcap_messages(self.topic)))
            return
        from kiss_icp.datasets.mcap import McapDataloader

        with guarded_loader("mcap", str(self.path)):
            self.loader = McapDataloader(str(self.path), topic=self.topic)
        self.n_scans = int(self.loader.n_scans)

    def _mcap_messages(self, topic: str) -> Iterator[Any]:
        """The raw MCAP messages of ``topic`` in log-time order, as kiss-icp's loader reads them."""
        from mcap.reader import make_reader

        with open(self.path, "rb") as fh:
            for _, _, message in make_reader(fh).iter_messages(topics=[topic], log_time_order=True):
                yield message

    def _messages(self, topic: str) -> Iterator[tuple[int, Any]]:
        # (a message that cannot be decoded is a DataError naming it: _read_all)
        if topic in self._ros1_schemas:
            from rosbags.typesys import Stores, get_typestore
            from rosbags.typesys.msg import get_types_from_msg

            msgtype, schema = self._ros1_schemas[topic]
            store = get_typestore(Stores.EMPTY)
            store.register(get_types_from_msg(schema.data.decode(), msgtype))
            for k, message in enumerate(self._mcap_messages(topic)):
                yield k, store.deserialize_ros1(message.data, msgtype)
            return
        for k, item in enumerate(self.loader.read_ros2_messages(str(self.path), topics=[topic])):
            yield k, item.ros_msg


def _option_word(value: Any, words: tuple[str, ...]) -> Any:
    """``value`` as the option word it spells in any case (``None``, ``NONE``: ``none``, which was taken for a field or
    topic name), ``null`` in any case None (the default, as a spec's ``null`` reads), else as given."""
    if isinstance(value, str):
        word = value.strip().lower()
        if word == "null":
            return None
        if word in words:
            return word
    return value


def _topic_named(given: Any, topics: dict[str, str]) -> Any:
    """``given`` as the bag names the topic: ``points`` is ``/points`` (a ROS name without its leading slash is in the
    root namespace; it was refused as "no topic 'points'" beside /points), else as given."""
    if isinstance(given, str) and given and given != "none" and given not in topics and f"/{given.lstrip('/')}" in topics:
        return f"/{given.lstrip('/')}"
    return given


def _ros2_type_name(name: str) -> str:
    """A ROS 1 message type under its ROS 2 name (``sensor_msgs/PointCloud2``: ``sensor_msgs/msg/PointCloud2``)."""
    package, _, message = name.rpartition("/")
    return f"{package}/msg/{message}" if package and "/" not in package else name


__all__ = ["McapScans", "RosbagScans", "bag_path", "guarded_loader", "interpolation_error_m", "require_modules", "sweep_instant_topic"]
