"""Write a simulated sequence as the files users record: ROS 1 bags, ROS 2 bags (sqlite3 or mcap) and MCAP.

One ``sensor_msgs/PointCloud2`` per sweep on ``/points`` with fields ``x y z intensity`` (float32), ``time``
(float32 seconds from the sweep start, as Velodyne drivers write it) and ``t`` (uint32 nanoseconds from the
sweep start, as Ouster drivers write it); the header stamp is the sweep start. One ``nav_msgs/Odometry`` per
sweep on ``/ground_truth`` with ``T_world_lidar`` at the config's ``pose_instant``, stamped at that instant, and the
true velocity there as its twist (in the lidar frame, the child frame); both covariances are zero (the motion is exact).
Beside it, one ``geometry_msgs/PoseStamped`` per sweep on each of ``/ground_truth/sweep_start``, ``/sweep_mid`` and
``/sweep_end``: the pose at that instant of the sweep, stamped there, so that the bag readers give the ground truth at
any instant as the simulator computes it (interpolating the one recorded instant was off by a dt^2/8 while the drive
pulls away, and sweep 0's start or the last sweep's end was continued at constant velocity).
Points are in firing order as :meth:`SimulatedLidarSequence.read_scan` returns them, rounded to float32 (read_scan
gives float64), so the bag and the KITTI-layout export hold the same sweeps, bit for bit, while odometry over either
differs slightly from odometry over the ``sim:`` spec itself. Written with the ``rosbags`` writers.
"""

from __future__ import annotations

import errno
import os
import sqlite3
from collections.abc import Callable
from pathlib import Path

import numpy as np

from lidarkit.errors import ConfigError, DataError, OutputError
from lidarkit.io.pointcloud2 import MAX_SWEEP_S
from lidarkit.io.rosbag import sweep_instant_topic

BAG_FORMATS = ("rosbag1", "rosbag2", "mcap")
STORAGES = ("sqlite3", "mcap")
POINTS_TOPIC = "/points"
GROUND_TRUTH_TOPIC = "/ground_truth"
FRAME_ID = "lidar"
#: the frame the ground-truth poses T_world_lidar are expressed in (the odometry message's header frame)
WORLD_FRAME_ID = "world"
#: the uint32 ``t`` field counts nanoseconds: a sweep longer than this overflows it
MAX_T_FIELD_SWEEP_S = (2**32 - 1) * 1e-9
_POINT_DTYPE = np.dtype({"names": ["x", "y", "z", "intensity", "time", "t"],
                         "formats": ["<f4", "<f4", "<f4", "<f4", "<f4", "<u4"], "offsets": [0, 4, 8, 12, 16, 20], "itemsize": 24})
_POINT_DTYPE_NO_TIMES = np.dtype({"names": ["x", "y", "z", "intensity"], "formats": ["<f4"] * 4, "offsets": [0, 4, 8, 12], "itemsize": 16})
_PF_FLOAT32, _PF_UINT32 = 7, 6  # sensor_msgs/PointField datatype codes


def check_bag_target(out: str | os.PathLike, fmt: str, option: str | None = None) -> Path:
    """``out`` as a bag of ``fmt`` may be named (as the readers and their detection recognise it) and is not there yet;
    ConfigError naming ``option`` (default: the path) for a name, DataError for an existing bag, OutputError for a
    dangling symbolic link. Checked again by :func:`export_bag`; the CLI calls it before simulating."""
    out = Path(out)
    suffix = {"rosbag1": ".bag", "mcap": ".mcap"}.get(fmt)
    if suffix is not None and out.suffix.lower() != suffix:  # (as the CLI and the readers' detection: run.MCAP is one)
        raise ConfigError(f"a {fmt} file is named *{suffix}, got {out.name!r}", source=option or out)
    if fmt == "rosbag1" and out.suffix != ".bag":  # (rosbags' reader opens X.Bag as an unknown storage format)
        raise ConfigError(f"a ROS 1 bag is read back only by a lower-case .bag name: name it {out.stem}.bag, got {out.name!r}",
                          source=option or out)
    if fmt == "rosbag2" and out.suffix.lower() in (".bag", ".mcap"):  # a ROS 2 bag is a folder: read as a file by that name
        raise ConfigError(f"a rosbag2 bag is a folder: name it without {out.suffix}, got {out.name!r}", source=option or out)
    if out.exists():
        raise DataError("exists already; bags are never overwritten", source=out)
    from lidarkit.atomic import refuse_dangling_link

    # (a dangling link: refused only after the simulation, as if another export had written it)
    refuse_dangling_link(out, "folder" if fmt == "rosbag2" else "file")
    return out


def export_bag(sequence, out: str | os.PathLike, fmt: str = "rosbag2", *, storage: str = "sqlite3",
               on_frame: Callable[[int], None] | None = None) -> Path:
    """Write ``sequence`` (a :class:`~lidarkit.sim.lidar.SimulatedLidarSequence`) to ``out`` and return it.

    ``fmt``: ``"rosbag1"`` (``out`` is a ``.bag`` file), ``"rosbag2"`` (``out`` is a bag folder; ``storage``
    ``"sqlite3"`` or ``"mcap"``) or ``"mcap"`` (``out`` is a ``.mcap`` file). The result appears only when
    complete (written beside it, then renamed); an existing ``out`` is an error, as with the ROS tools.
    """
    from lidarkit.sim.lidar import SimulatedLidarSequence, check_argument

    check_argument(sequence, SimulatedLidarSequence, "sequence")
    check_argument(out, (str, os.PathLike), "out", "a path")
    if fmt not in BAG_FORMATS:
        raise ConfigError(f"unknown bag format {fmt!r}; known: {', '.join(BAG_FORMATS)}", source="format")
    if storage not in STORAGES:
        raise ConfigError(f"unknown ROS 2 storage {storage!r}; known: {', '.join(STORAGES)}", source="storage")
    if storage != "sqlite3" and fmt != "rosbag2":  # (as the CLI refuses --storage without --format rosbag2)
        raise ConfigError(f"a storage is chosen for ROS 2 bags only, not for {fmt}", source="storage")
    try:
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise ConfigError("writing bags needs the Python package 'rosbags': pip install 'lidarkit[ros]'", source=f"format {fmt}") from None
    out = check_bag_target(out, fmt)
    period = sequence.config.sweep_period_s
    if period > MAX_T_FIELD_SWEEP_S and sequence.config.sweeps_carry_point_times:  # (a 5 s sweep wrapped its t values past
        # 4.29 s back to 0; clouds without per-point times have no t field to overflow)
        raise ConfigError(f"a sweep of {period:g} s overflows the uint32 nanosecond 't' field drivers write (at most "
                          f"{MAX_T_FIELD_SWEEP_S:.3g} s): frame_rate_hz must be at least {1 / MAX_T_FIELD_SWEEP_S:.3g} for a bag",
                          source="frame_rate_hz")
    if period > MAX_SWEEP_S and sequence.config.sweeps_carry_point_times:  # (a 1.1 s sweep was written, then refused by
        # lidarkit's own bag readers: its times spanned more than a sweep lasts)
        raise ConfigError(f"a sweep of {period:g} s is longer than the {MAX_SWEEP_S:g} s lidarkit's bag readers accept (they "
                          f"would refuse its per-point times): frame_rate_hz must be at least {1 / MAX_SWEEP_S:g} for a bag",
                          source="frame_rate_hz")
    from lidarkit import atomic

    # a partial output: one left by a killed export (kill -9) is removed by the next one after an hour
    with atomic.partial_folder(out) as scratch:
        if fmt == "rosbag1":
            from rosbags.rosbag1 import Writer

            typestore = get_typestore(Stores.ROS1_NOETIC)
            target = scratch / out.name
            writer = Writer(target)
            serialize = typestore.serialize_ros1
        else:
            from rosbags.rosbag2 import StoragePlugin, Writer

            typestore = get_typestore(Stores.ROS2_HUMBLE)
            target = scratch / "bag"
            plugin = StoragePlugin.MCAP if (fmt == "mcap" or storage == "mcap") else StoragePlugin.SQLITE3
            writer = Writer(target, version=8, storage_plugin=plugin)
            serialize = typestore.serialize_cdr
        # a full disk (or a file-size limit) mid-write: one line naming the output (it was a traceback of the writer's
        # OSError, or of sqlite3's "disk I/O error" for a ROS 2 bag in sqlite3 storage)
        try:
            with atomic.output_errors(out):
                _write_messages(sequence, writer, typestore, serialize, ros1=fmt == "rosbag1", on_frame=on_frame)
        except sqlite3.Error as err:
            raise OutputError(f"cannot write: {err} (is the disk full?)", source=out) from err
        if fmt == "mcap":
            target = next(target.glob("*.mcap"))
        with atomic.output_errors(out):
            _claim(target, out)
    return out


def _claim(written: Path, out: Path) -> None:
    """Move the written bag to ``out`` unless something got there while it was written (another export: it replaced
    that one before): a file is linked (refused when ``out`` exists), a ROS 2 bag folder renamed (refused onto a
    folder that holds files)."""
    try:
        if written.is_dir():
            os.rename(written, out)
        else:
            os.link(written, out)
    except OSError as err:
        if err.errno in (errno.EEXIST, errno.ENOTEMPTY, errno.EISDIR, errno.ENOTDIR):
            raise OutputError("a bag appeared there while this one was written (another export?): it is kept, this one is "
                              "not written", source=out) from None
        if err.errno not in (errno.EPERM, errno.ENOTSUP, errno.EXDEV) or out.exists():
            raise
        os.replace(written, out)  # a file system without hard links: the check above is as close as it gets


#: half the interval of the central differences that give the true velocity: 1 cm of a 10 m/s drive (less than the
#: path's 0.1 m sample step); the sway (at most 1.2 Hz) differentiated to 1e-5 of its rate
TWIST_HALF_STEP_S = 1e-3


def true_twists(sequence, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear (m/s) and angular (rad/s) velocity ``(N, 3)`` float64 of the lidar at ``times_s`` ``(N,)``, both in the
    lidar frame, as a nav_msgs/Odometry twist is given in its child frame: central differences of the simulated drive
    (``poses_at``) over ``TWIST_HALF_STEP_S`` either side, the angular rate from the relative rotation's axis-angle."""
    from scipy.spatial.transform import Rotation

    times_s = np.asarray(times_s, dtype=np.float64)
    before, at, after = (sequence.poses_at(times_s + dt) for dt in (-TWIST_HALF_STEP_S, 0.0, TWIST_HALF_STEP_S))
    linear_mps = np.einsum("nji,nj->ni", at[:, :3, :3], after[:, :3, 3] - before[:, :3, 3]) / (2.0 * TWIST_HALF_STEP_S)
    turn = np.einsum("nji,njk->nik", before[:, :3, :3], after[:, :3, :3])  # R(t-h)^T R(t+h) = exp(2 h [w_lidar]x)
    angular_radps = Rotation.from_matrix(turn).as_rotvec() / (2.0 * TWIST_HALF_STEP_S)
    return linear_mps, angular_radps


def _write_messages(sequence, writer, typestore, serialize, *, ros1: bool, on_frame) -> None:
    from scipy.spatial.transform import Rotation

    from lidarkit.sim.lidar import POSE_INSTANTS

    T = typestore.types
    pc2, odom, stamped = "sensor_msgs/msg/PointCloud2", "nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped"
    # without per-point times (point_times=false) the clouds have no time fields, as a driver that writes none; nor
    # does a snapshot (motion_distortion=false: every point at one instant, zeros would read as a sweep's times),
    # whose header is stamped at that instant (the sweep start read 0.1 s before its ground truth)
    snapshot = not sequence.config.motion_distortion
    dtype = _POINT_DTYPE if sequence.config.sweeps_carry_point_times else _POINT_DTYPE_NO_TIMES
    stamps = sequence.timestamps_s
    fields = [T["sensor_msgs/msg/PointField"](name=n, offset=dtype.fields[n][1], datatype=_PF_UINT32 if n == "t" else _PF_FLOAT32, count=1)
              for n in dtype.names]
    gt = sequence.ground_truth
    quat_xyzw = Rotation.from_matrix(gt.poses_se3[:, :3, :3]).as_quat()
    at_instants = {instant: sequence.ground_truth_at(instant) for instant in POSE_INSTANTS}
    period = sequence.config.sweep_period_s

    def header(seq: int, t_s: float, frame_id: str = FRAME_ID):
        # (whole nanoseconds first: 49 sweeps at 49 Hz end at 0.9999999999999999 s, which was sec 0, nanosec 1e9, out
        # of ROS's range)
        sec, nanosec = divmod(int(round(t_s * 1e9)), 1_000_000_000)
        stamp = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)
        if ros1:
            return T["std_msgs/msg/Header"](seq=seq, stamp=stamp, frame_id=frame_id)
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)

    def pose_msg(pose: np.ndarray, q: np.ndarray):
        return T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=pose[0, 3], y=pose[1, 3], z=pose[2, 3]),
                                           orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))

    zeros36 = np.zeros(36)
    vec = T["geometry_msgs/msg/Vector3"]
    instant_quats = {instant: Rotation.from_matrix(traj.poses_se3[:, :3, :3]).as_quat() for instant, traj in at_instants.items()}
    linear_mps, angular_radps = true_twists(sequence, gt.timestamps_s)
    with writer:
        points_conn = writer.add_connection(POINTS_TOPIC, pc2, typestore=typestore)
        gt_conn = writer.add_connection(GROUND_TRUTH_TOPIC, odom, typestore=typestore)
        instant_conns = {instant: writer.add_connection(sweep_instant_topic(GROUND_TRUTH_TOPIC, instant), stamped, typestore=typestore)
                         for instant in POSE_INSTANTS}
        for i in range(len(sequence)):
            scan = sequence.read_scan(i)
            cloud = np.zeros(len(scan.points_xyz), dtype=dtype)
            for k, axis in enumerate("xyz"):
                cloud[axis] = scan.points_xyz[:, k]
            cloud["intensity"] = 0.0 if scan.intensity is None else scan.intensity
            if scan.point_times_s is not None:
                cloud["time"] = scan.point_times_s
                cloud["t"] = np.round(scan.point_times_s * 1e9).astype(np.uint32)
            start_s = float(stamps[i]) if snapshot else i * period
            msg = T[pc2](header=header(i, start_s), height=1, width=len(cloud), fields=fields, is_bigendian=False,
                         point_step=dtype.itemsize, row_step=dtype.itemsize * len(cloud),
                         data=cloud.view(np.uint8).ravel(), is_dense=True)
            writer.write(points_conn, int(round(start_s * 1e9)), serialize(msg, pc2))
            odom_msg = T[odom](
                header=header(i, float(gt.timestamps_s[i]), WORLD_FRAME_ID), child_frame_id=FRAME_ID,
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose_msg(gt.poses_se3[i], quat_xyzw[i]), covariance=zeros36),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](linear=vec(x=linear_mps[i, 0], y=linear_mps[i, 1], z=linear_mps[i, 2]),
                                                       angular=vec(x=angular_radps[i, 0], y=angular_radps[i, 1], z=angular_radps[i, 2])),
                    covariance=zeros36),
            )
            writer.write(gt_conn, int(round(float(gt.timestamps_s[i]) * 1e9)), serialize(odom_msg, odom))
            for instant, traj in at_instants.items():
                t_s = float(traj.timestamps_s[i])
                msg = T[stamped](header=header(i, t_s, WORLD_FRAME_ID), pose=pose_msg(traj.poses_se3[i], instant_quats[instant][i]))
                writer.write(instant_conns[instant], int(round(t_s * 1e9)), serialize(msg, stamped))
            if on_frame is not None:
                on_frame(i)


__all__ = ["BAG_FORMATS", "GROUND_TRUTH_TOPIC", "POINTS_TOPIC", "STORAGES", "check_bag_target", "export_bag", "true_twists"]
