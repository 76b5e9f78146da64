"""The LiDAR simulator: exact geometry, determinism, per-point times, motion distortion, pose instants, export."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from lidarkit.errors import ConfigError, DataError
from lidarkit.geometry import rotation_angle_deg, se3_inverse
from lidarkit.io.base import ScanSequence
from lidarkit.sim.lidar import SimulatedLidarSequence, export_kitti, make_config, open_sim
from lidarkit.trajectory import Trajectory

SMALL = dict(n_beams=16, n_azimuths=360, n_frames=6)


def _mesh_distance_m(seq: SimulatedLidarSequence, points_world: np.ndarray) -> np.ndarray:
    """Unsigned distance of world points to the scene's triangles."""
    return seq.scene.compute_distance(o3d.core.Tensor(points_world.astype(np.float32))).numpy().astype(np.float64)


def _to_world(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (N, 3) through poses T (N, 4, 4) or one pose (4, 4)."""
    if T.ndim == 2:
        return points @ T[:3, :3].T + T[:3, 3]
    return np.einsum("nij,nj->ni", T[:, :3, :3], points) + T[:, :3, 3]


def test_ground_plane_ranges_match_closed_form():
    h = 1.73
    seq = SimulatedLidarSequence(
        scene="ground", n_beams=8, elevation_max_deg=-5.0, elevation_min_deg=-24.0, n_azimuths=90,
        n_frames=2, sensor_height_m=h, motion_distortion=False, sway_deg=0.0, heave_m=0.0,
    )
    scan = seq.read_scan(1)
    assert len(scan.points_xyz) == 8 * 90  # every downward beam hits the plane within 80 m
    horizontal_m = np.hypot(scan.points_xyz[:, 0], scan.points_xyz[:, 1])
    elevation = np.arctan2(scan.points_xyz[:, 2], horizontal_m)
    # each point's elevation is one of the beams, and the beam at elevation -e hits at h / tan(e)
    beam = np.abs(elevation[:, None] - seq.elevation_rad[None, :]).argmin(axis=1)
    np.testing.assert_allclose(elevation, seq.elevation_rad[beam], atol=1e-9)
    np.testing.assert_allclose(horizontal_m, h / np.tan(-seq.elevation_rad[beam]), rtol=1e-5)
    np.testing.assert_allclose(scan.points_xyz[:, 2], -h, atol=1e-4)


def test_beams_above_horizon_and_max_range_return_nothing():
    seq = SimulatedLidarSequence(scene="ground", n_beams=4, elevation_max_deg=1.0, elevation_min_deg=-2.0, n_azimuths=36, n_frames=1, max_range_m=60.0, sway_deg=0.0, heave_m=0.0)
    scan = seq.read_scan(0)
    # -1 deg hits at 99 m (> 60 m max range), +1 and 0 never hit: only the -2 deg beam (49.5 m) returns
    assert len(scan.points_xyz) == 36
    np.testing.assert_allclose(np.linalg.norm(scan.points_xyz, axis=1), 1.73 / np.sin(np.deg2rad(2.0)), rtol=1e-5)


def test_range_noise_has_the_configured_std():
    sigma = 0.05
    seq = SimulatedLidarSequence(scene="ground", n_beams=16, elevation_max_deg=-6.0, n_azimuths=400, n_frames=1, range_noise_std_m=sigma, sway_deg=0.0, heave_m=0.0)
    scan = seq.read_scan(0)
    range_m = np.linalg.norm(scan.points_xyz, axis=1)
    direction = scan.points_xyz / range_m[:, None]
    residual = range_m - 1.73 / -direction[:, 2]
    assert abs(residual.mean()) < 0.005
    assert residual.std() == pytest.approx(sigma, rel=0.05)


def test_deterministic_per_seed():
    cfg = dict(SMALL, range_noise_std_m=0.02)
    a = SimulatedLidarSequence(scene="street", seed=3, **cfg).read_scan(4)
    b = SimulatedLidarSequence(scene="street", seed=3, **cfg).read_scan(4)
    assert np.array_equal(a.points_xyz, b.points_xyz)
    assert np.array_equal(a.intensity, b.intensity)
    c_seq = SimulatedLidarSequence(scene="street", seed=4, **cfg)
    c = c_seq.read_scan(4)
    assert len(c.points_xyz) != len(a.points_xyz) or not np.allclose(c.points_xyz, a.points_xyz)
    gt_a = SimulatedLidarSequence(scene="street", seed=3, **cfg).ground_truth.poses_se3
    assert np.abs(gt_a - c_seq.ground_truth.poses_se3).max() > 1e-4  # the drive depends on the seed too
    # a longer sequence with the same seed starts with the same sweeps (scene and path are prefix-stable)
    longer = SimulatedLidarSequence(scene="street", seed=3, **dict(cfg, n_frames=40))
    assert np.array_equal(longer.read_scan(4).points_xyz, a.points_xyz)
    np.testing.assert_array_equal(longer.ground_truth.poses_se3[:6], gt_a)


def test_point_times_follow_azimuth():
    """Column firing times, clockwise from the rear; a snapshot (no motion distortion) carries none: deskewing it with
    its columns' times moved its points off the surfaces (up to 1 m)."""
    assert SimulatedLidarSequence(scene="street", motion_distortion=False, **SMALL).read_scan(2).point_times_s is None
    # frame 0 starts at rest (the vehicle pulls away over accel_time_s): the sweep is as good as a snapshot
    seq = SimulatedLidarSequence(scene="street", accel_time_s=20.0, sway_deg=0.0, heave_m=0.0, **SMALL)
    scan = seq.read_scan(0)
    times = scan.point_times_s
    assert times is not None and times.shape == (len(scan.points_xyz),)
    assert np.all(np.diff(times) >= 0.0)  # points are ordered by firing time
    period = seq.config.sweep_period_s
    assert times.min() >= 0.0 and times.max() < period
    # clockwise from the rear: time = (pi - azimuth) mod 2 pi / (2 pi) * period, to 1e-6 of a column
    azimuth = np.arctan2(scan.points_xyz[:, 1], scan.points_xyz[:, 0])
    offset = np.mod(np.pi - azimuth + 1e-9, 2.0 * np.pi) - 1e-9
    np.testing.assert_allclose(times, offset / (2.0 * np.pi) * period, atol=1e-6 * period / 360)


def test_motion_distortion_follows_the_per_column_poses():
    distorted = SimulatedLidarSequence(scene="street", accel_time_s=0.0, **SMALL)
    scan = distorted.read_scan(3)
    sweep_start = 3 * distorted.config.sweep_period_s
    column_poses = distorted.poses_at(sweep_start + scan.point_times_s)
    above_ground = scan.points_xyz[:, 2] > -1.5
    pts = scan.points_xyz[above_ground]
    # exact per-column poses put every point on the scene surfaces ...
    exact = _mesh_distance_m(distorted, _to_world(column_poses[above_ground], pts))
    assert np.percentile(exact, 99) < 2e-3
    # ... one pose for the whole sweep does not: late columns are off by up to a frame's motion (1 m)
    late = scan.point_times_s[above_ground] > 0.75 * distorted.config.sweep_period_s
    naive = _mesh_distance_m(distorted, _to_world(distorted.poses_at(np.array([sweep_start]))[0], pts))
    assert np.percentile(naive[late], 90) > 0.3  # (facades parallel to the motion hide the shift: a percentile)
    early = scan.point_times_s[above_ground] < 0.05 * distorted.config.sweep_period_s
    assert np.percentile(naive[early], 99) < 0.06  # the first columns moved by at most 5 cm
    # an undistorted sweep is consistent with the single ground-truth pose
    undistorted = SimulatedLidarSequence(scene="street", accel_time_s=0.0, motion_distortion=False, **SMALL)
    snap = undistorted.read_scan(3)
    keep = snap.points_xyz[:, 2] > -1.5
    d = _mesh_distance_m(undistorted, _to_world(undistorted.ground_truth.poses_se3[3], snap.points_xyz[keep]))
    assert np.percentile(d, 99) < 2e-3
    assert len(snap.points_xyz) != len(scan.points_xyz) or not np.allclose(snap.points_xyz, scan.points_xyz)


def test_mid_and_end_poses_differ_by_half_a_frame():
    seq = SimulatedLidarSequence(scene="street", speed_mps=12.0, accel_time_s=0.0, sway_deg=0.0, heave_m=0.0, **SMALL)
    start, mid, end = (seq.ground_truth_at(k) for k in ("start", "mid", "end"))
    assert seq.ground_truth.meta["pose_instant"] == "end"  # the default: kiss-icp deskews to the sweep end
    np.testing.assert_allclose(seq.timestamps_s, end.timestamps_s)
    np.testing.assert_allclose(end.timestamps_s - mid.timestamps_s, 0.05)
    half_frame_m = 12.0 * 0.1 / 2
    np.testing.assert_allclose(np.linalg.norm(end.positions_xyz - mid.positions_xyz, axis=1), half_frame_m, rtol=1e-4)
    np.testing.assert_allclose(np.linalg.norm(mid.positions_xyz - start.positions_xyz, axis=1), half_frame_m, rtol=1e-4)
    # the end of sweep i is the start of sweep i + 1
    np.testing.assert_allclose(end.poses_se3[:-1], start.poses_se3[1:], atol=1e-12)
    # rotation: mid is halfway between start and end
    full = rotation_angle_deg(se3_inverse(start.poses_se3) @ end.poses_se3)
    first_half = rotation_angle_deg(se3_inverse(start.poses_se3) @ mid.poses_se3)
    second_half = rotation_angle_deg(se3_inverse(mid.poses_se3) @ end.poses_se3)
    np.testing.assert_allclose(first_half + second_half, full, atol=1e-6)  # planar: yaw angles add up
    np.testing.assert_allclose(second_half, full / 2, rtol=0.05)  # (the curvature varies a little in a frame)
    assert np.allclose(start.poses_se3[0], np.eye(4))  # world origin = sensor at the start of sweep 0


def test_drive_starts_at_rest_and_reaches_cruise_speed():
    seq = SimulatedLidarSequence(scene="ground", speed_mps=10.0, accel_time_s=2.0, n_beams=4, n_azimuths=36, n_frames=40, heave_m=0.0)
    step_m = np.linalg.norm(np.diff(seq.ground_truth_at("start").positions_xyz, axis=0), axis=1)
    assert step_m[0] < 0.01  # at rest at t = 0 (0.1 s of a smoothstep ramp: 0.0049 m)
    assert np.all(np.diff(step_m[:20]) > 0)  # accelerating
    np.testing.assert_allclose(step_m[20:], 1.0, rtol=1e-3)  # 10 m/s x 0.1 s once the ramp is over
    assert seq.distance_at(np.array([2.0]))[0] == pytest.approx(10.0)  # half the cruise distance during the ramp


def test_body_sways_around_the_planar_drive():
    seq = SimulatedLidarSequence(scene="ground", sway_deg=0.5, heave_m=0.03, n_beams=4, n_azimuths=36, n_frames=100)
    T = seq.ground_truth.poses_se3
    pitch = np.degrees(np.arcsin(-T[:, 2, 0]))
    roll = np.degrees(np.arctan2(T[:, 2, 1], T[:, 2, 2]))
    assert 0.3 < np.abs(pitch).max() <= 1.0 + 1e-9 and 0.3 < np.abs(roll).max() <= 1.0 + 1e-9  # amplitude 0.5 deg around a start at 0
    assert 0.01 < np.abs(T[:, 2, 3]).max() <= 0.06 + 1e-9
    np.testing.assert_allclose(np.swapaxes(T[:, :3, :3], 1, 2) @ T[:, :3, :3], np.broadcast_to(np.eye(3), (100, 3, 3)), atol=1e-12)
    flat = SimulatedLidarSequence(scene="ground", sway_deg=0.0, heave_m=0.0, n_beams=4, n_azimuths=36, n_frames=100)
    np.testing.assert_array_equal(flat.ground_truth.poses_se3[:, 2], np.broadcast_to([0.0, 0.0, 1.0, 0.0], (100, 4)))


def test_is_a_scan_sequence_and_checks_input():
    seq = SimulatedLidarSequence(scene="open", **SMALL)
    assert isinstance(seq, ScanSequence)
    assert len(seq) == 6 and len(seq.ground_truth) == 6
    with pytest.raises(DataError, match="frame index 6 out of range for 6 frames"):
        seq.read_scan(6)
    with pytest.raises(ConfigError, match="n_beams"):
        make_config(n_beams=0)
    with pytest.raises(ConfigError, match="valid:"):
        make_config(beamz=3)
    with pytest.raises(ConfigError, match="pose instant"):
        seq.ground_truth_at("middle")
    with pytest.raises(ConfigError, match="elevation_min_deg"):
        make_config(elevation_min_deg=5.0, elevation_max_deg=2.0)
    with pytest.raises(ConfigError, match=r"open_object_lateral_m min 2 m would put the open scene's boxes .* at least 5 m"):
        make_config(scene="open", open_object_lateral_m=(2.0, 10.0))


def test_a_negative_sweep_index_counts_from_the_end_as_the_file_readers_do():
    """read_scan(-1) is the last scan of a KITTI sequence or a scan folder; the simulator refused it ("frame index -1
    out of range for 6 frames"). The sweep read is the same one, noise and per-point times included."""
    seq = SimulatedLidarSequence(scene="open", range_noise_std_m=0.02, n_beams=8, n_azimuths=90, n_frames=6)
    last, first = seq.read_scan(5), seq.read_scan(0)
    for scan, same in ((seq.read_scan(-1), last), (seq.read_scan(np.int64(-6)), first)):
        np.testing.assert_array_equal(scan.points_xyz, same.points_xyz)
        np.testing.assert_array_equal(scan.point_times_s, same.point_times_s)
    np.testing.assert_array_equal(seq.read_scan_labels(-1)[1], seq.read_scan_labels(5)[1])
    with pytest.raises(DataError, match="frame index -7 out of range for 6 frames"):
        seq.read_scan(-7)


def test_open_objects_at_the_nearest_allowed_band_leave_the_path_free():
    """At the clearance bound, the open scene's objects stay more than 0.75 m from the sensor's path (it never drives
    through a box; at 2 m it passes within 4 mm of one, which the config check refuses)."""
    from lidarkit.sim.lidar import LABELS, OPEN_OBJECT_CLEARANCE_M

    seq = SimulatedLidarSequence(make_config(scene="open", n_frames=600, open_object_lateral_m=(OPEN_OBJECT_CLEARANCE_M, OPEN_OBJECT_CLEARANCE_M + 0.1)))
    objects = seq.triangles[seq.triangle_labels != LABELS["ground"]]
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(seq.vertices_xyz.astype(np.float32), objects.astype(np.uint32))
    path = np.c_[seq.path.xy_m, np.zeros(len(seq.path.xy_m))].astype(np.float32)  # the sensor's height (z = 0)
    assert len(objects) > 100 and scene.compute_distance(path).numpy().min() > 0.75


def test_spec_string():
    seq = open_sim("sim:open?frames=5&beams=16&azimuths=360&noise=0.01&instant=mid&distortion=false&seed=7")
    cfg = seq.config
    assert (cfg.scene, cfg.n_frames, cfg.n_beams, cfg.n_azimuths) == ("open", 5, 16, 360)
    assert (cfg.range_noise_std_m, cfg.pose_instant, cfg.motion_distortion, cfg.seed) == (0.01, "mid", False, 7)
    with pytest.raises(ConfigError, match="sim:forest"):
        open_sim("sim:forest")
    with pytest.raises(ConfigError, match="n_frames"):
        open_sim("sim:street?frames=-1")
    with pytest.raises(ConfigError, match=r"n_frames is given twice \(as frames and n_frames\)"):  # ("(as n_frames)")
        open_sim("sim:street?frames=4&n_frames=5")
    with pytest.raises(ConfigError, match=r"scene is given twice \(as sim:street and scene\)"):
        open_sim("sim:street?scene=open")
    # a typo lists the short keys the help gives too (the config's list had only the long names)
    with pytest.raises(ConfigError, match=r"unknown key 'frame'; short keys: frames \(n_frames\), beams \(n_beams\).*; or any of: scene, n_frames"):
        open_sim("sim:street?frame=3")


def test_export_kitti_round_trip(tmp_path):
    seq = SimulatedLidarSequence(scene="street", n_beams=8, n_azimuths=180, n_frames=3, pose_instant="mid")
    out = export_kitti(seq, tmp_path / "seq")
    scan = seq.read_scan(2)
    data = np.fromfile(out / "velodyne" / "000002.bin", dtype=np.float32).reshape(-1, 4)
    np.testing.assert_allclose(data[:, :3], scan.points_xyz, atol=1e-4)
    np.testing.assert_allclose(np.load(out / "point_times" / "000002.npy"), scan.point_times_s, atol=1e-7)
    poses = Trajectory.from_kitti(out / "poses.txt", out / "times.txt")
    np.testing.assert_allclose(poses.poses_se3, seq.ground_truth_at("mid").poses_se3, atol=1e-6)
    np.testing.assert_allclose(poses.timestamps_s, seq.ground_truth_at("mid").timestamps_s, atol=1e-6)
    end = Trajectory.from_kitti(out / "poses_end.txt")
    np.testing.assert_allclose(end.poses_se3, seq.ground_truth_at("end").poses_se3, atol=1e-6)
    assert "Tr:" in (out / "calib.txt").read_text()


def test_a_drive_too_long_to_build_is_refused_before_any_allocation():
    """100 million frames (or a 1e30 m range) is a one-line ConfigError, not a process the OOM killer ends."""
    from lidarkit.sim.lidar import MAX_DRIVE_M, make_config

    with pytest.raises(ConfigError, match=r"the drive is 500.2 km long .* at most 200 km"):
        make_config(n_frames=500_000)
    with pytest.raises(ConfigError, match="max_range_m: Input should be less than or equal to 1000"):
        make_config(max_range_m=1e30)
    with pytest.raises(ConfigError, match="n_frames: Input should be less than or equal to 1000000"):
        make_config(n_frames=100_000_000, speed_mps=0.001)  # a short drive of many sweeps: their stamps and poses
    longest = make_config(n_frames=int(MAX_DRIVE_M / 1.0) - 400, speed_mps=10.0)  # 1 m a frame: just within the bound
    assert longest.drive_length_m <= MAX_DRIVE_M


def test_export_kitti_is_all_or_nothing_and_never_mixes_two_exports(tmp_path):
    """An export that fails part-way leaves no folder that reads as a sequence; a folder holding files is refused
    (3 sweeps written over 5 used to leave sweeps 3-4 of the old export beside the new poses)."""
    from lidarkit.errors import OutputError

    seq = SimulatedLidarSequence(scene="street", n_beams=8, n_azimuths=180, n_frames=5)

    def fail_at_3(i):
        if i == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        export_kitti(seq, tmp_path / "cut", on_frame=fail_at_3)
    assert not (tmp_path / "cut").exists() and list(tmp_path.iterdir()) == []
    export_kitti(seq, tmp_path / "seq")
    with pytest.raises(OutputError, match="seq: the folder already holds files"):
        export_kitti(SimulatedLidarSequence(scene="street", n_beams=8, n_azimuths=180, n_frames=3), tmp_path / "seq")
    assert len(list((tmp_path / "seq" / "velodyne").iterdir())) == 5
    (tmp_path / "empty").mkdir()
    assert len(list((export_kitti(seq, tmp_path / "empty") / "velodyne").iterdir())) == 5  # an empty folder is used


def test_scenes_and_images_too_large_for_memory_are_refused_before_building(monkeypatch):
    """Hills over a long drive mesh the path's bounding box (3000 sweeps of 10 m hills: 37.5 M vertices, 11.5 GB) and
    a camera image allocates ~300 B a pixel (8192 x 8192 allowed: 19 GB): both ended in MemoryError tracebacks."""
    import lidarkit.resources
    from lidarkit.sim.street_camera import SimulatedCameraSequence

    monkeypatch.setattr(lidarkit.resources, "available_memory_bytes", lambda: 2 * 2**30)
    with pytest.raises(ConfigError, match=r"terrain_amplitude_m / terrain_wavelength_m / n_frames: the hills' ground mesh \(3.75e\+07 "
                                          r"vertices every 0.4 m over 4 x 1.5 km around the path\) needs about 10.5 GiB"):
        SimulatedLidarSequence(n_frames=3000, terrain_amplitude_m=0.5, terrain_wavelength_m=10.0)
    with pytest.raises(ConfigError, match=r"width / height: a 4096x4096 image needs about 4.69 GiB of memory, more than 80% of the 2 GiB available"):
        SimulatedCameraSequence(width=4096, height=4096, n_frames=2)
    assert len(SimulatedLidarSequence(n_frames=20, terrain_amplitude_m=1.0)) == 20  # what fits is built


def test_settings_of_scene_parts_that_are_not_drawn_are_refused():
    """open_object_lateral_m on the street scene and occluder_start without occluder=true were accepted and ignored."""
    from lidarkit.sim.street_camera import make_camera_config

    with pytest.raises(ConfigError, match="open_object_lateral_m places the open scene's objects; the street scene has none of them"):
        make_config(scene="street", open_object_lateral_m=(6.0, 9.0))
    with pytest.raises(ConfigError, match="occluder_start / occluder_frames place the occluder, and occluder=false draws none"):
        make_camera_config(occluder_start=10)
    assert make_camera_config(occluder=True, occluder_start=1, n_frames=5).occluder_start == 1


def test_a_path_curving_through_the_facades_is_refused():
    """max_curvature_per_m=0.2 (a 5 m radius) drove the sensor through the street's buildings (77 % of the returns
    within 3 m): bounded at 1/30, the street's facades standing 9-13 m from the path."""
    with pytest.raises(ConfigError, match=r"max_curvature_per_m: Input should be less than or equal to 0.0333"):
        make_config(max_curvature_per_m=0.2)
    seq = SimulatedLidarSequence(n_frames=41, n_beams=16, n_azimuths=360, max_curvature_per_m=1.0 / 30.0, seed=0)
    ranges = np.linalg.norm(seq.read_scan(40).points_xyz, axis=1)
    assert np.mean(ranges < 3.0) < 0.05  # the tightest curve allowed keeps the street around the sensor


def test_read_scan_refuses_a_non_integer_index():
    """read_scan(2.7) cast frame 2 without a word (int() truncated it); an index that is no integer is a DataError
    naming it, while numpy integers still read."""
    seq = SimulatedLidarSequence(n_frames=4, n_beams=8, n_azimuths=90)
    for index in (2.7, 2.0, "1", True):
        with pytest.raises(DataError) as err:
            seq.read_scan(index)
        assert (err.value.source, err.value.reason) == ("sim:street?seed=0", f"frame index {index!r} is not an integer")
    with pytest.raises(DataError, match=r"frame index 0.5 is not an integer"):
        seq.read_scan_labels(0.5)
    assert np.array_equal(seq.read_scan(np.int64(2)).points_xyz, seq.read_scan(2).points_xyz)


def test_a_yes_or_no_value_for_a_number_is_refused_in_both_simulators():
    """true/yes/on/off read as 1 or 0 without a word: -p n_beams=true cast one beam, speed=off stood still, seed=yes was
    seed 1, the camera's noise_std=true added noise of 1 grey level. Booleans stay booleans."""
    from lidarkit.sim.street_camera import make_camera_config

    with pytest.raises(ConfigError) as err:
        open_sim("sim:street?beams=true&speed=off&seed=yes&frames=2")
    assert err.value.reason == ("seed: takes a number, not a yes/no value (True); n_beams: takes a number, not a yes/no value "
                                "(True); speed_mps: takes a number, not a yes/no value (False)")
    with pytest.raises(ConfigError) as err:
        make_camera_config(noise_std=True, threads=True)
    assert (err.value.source, err.value.reason) == ("camera simulator", "threads: takes a number, not a yes/no value (True); "
                                                    "noise_std: takes a number, not a yes/no value (True)")
    with pytest.raises(ConfigError, match=r"^camera simulator: cx: takes a number, not a yes/no value \(False\)$"):  # (float | None too)
        make_camera_config(cx=False)
    with pytest.raises(ConfigError, match=r"^lidar simulator: open_object_lateral_m: takes a number, not a yes/no value \(True\)$"):
        make_config(scene="open", open_object_lateral_m=[True, 10])  # (read as 1 m, refused as too near the path)
    assert open_sim("sim:street?distortion=off&frames=2").config.motion_distortion is False
    assert make_camera_config(occluder=True, cx=None).occluder is True and make_config(n_beams=np.int64(8)).n_beams == 8


def test_cli_errors_name_the_option_and_list_the_valid_keys_for_an_unknown_one_only(tmp_path, capsys):
    """-n 0 said "lidar simulator: n_frames: Input should be greater than or equal to 1 (valid: scene, ... 23 names)":
    the option is named and the valid keys listed for an unknown key only; --storage MCAP said "storage: ..." after the
    scene was built; a tuple given as 5,10 was "Input should be a valid tuple" with no hint of [5,10]."""
    from lidarkit.cli import main

    def err(*args):
        with pytest.raises(SystemExit) as exc:
            main(["sim", *args, "--out", str(tmp_path / "x"), "--no-progress"])
        assert exc.value.code == 1
        return capsys.readouterr().err

    assert err("lidar", "-n", "0") == "error: --frames/-n: Input should be greater than or equal to 1\n"
    assert err("lidar", "--seed", "-1") == "error: --seed: Input should be greater than or equal to 0\n"
    assert err("lidar", "--scene", "forest") == "error: --scene: Input should be 'street', 'open' or 'ground'\n"
    assert err("camera", "-n", "0") == "error: --frames/-n: Input should be greater than or equal to 2\n"
    assert err("lidar", "-f", "rosbag2", "--storage", "MCAP") == "error: --storage: unknown ROS 2 storage 'MCAP'; known: sqlite3, mcap\n"
    assert err("lidar", "--scene", "open", "-p", "open_object_lateral_m=5,10") == (
        "error: lidar simulator: open_object_lateral_m: Input should be a valid tuple (write it as [5,10])\n")
    assert err("lidar", "-n", "0", "-p", "n_beams=0") == ("error: lidar simulator: --frames/-n: Input should be greater than or "
                                                          "equal to 1; n_beams: Input should be greater than or equal to 1\n")
    assert err("lidar", "-p", "beamz=2").startswith("error: lidar simulator: beamz: Extra inputs are not permitted (valid: scene, "
                                                    "n_frames, seed, n_beams,")
    assert not (tmp_path / "x").exists()


def test_a_wrong_kind_of_argument_is_a_config_error_naming_it(tmp_path):
    """A dict for the config, a LiDAR config for the camera, a spec string for a sequence or None for a spec ended in an
    AttributeError (or a TypeError) deep inside the simulators and exports."""
    from lidarkit.sim.bag_export import export_bag
    from lidarkit.sim.lidar import LidarSimConfig
    from lidarkit.sim.street_camera import SimulatedCameraSequence, export_kitti_images, open_simcam

    calls = [
        (lambda: SimulatedLidarSequence({"n_frames": 3}), "config: takes a LidarSimConfig (or keyword parameters), got dict {'n_frames': 3}"),
        (lambda: SimulatedCameraSequence(LidarSimConfig(n_frames=3)), "config: takes a CameraSimConfig (or keyword parameters), got LidarSimConfig"),
        (lambda: export_kitti("sim:street", tmp_path / "zz"), "sequence: takes a SimulatedLidarSequence, got str 'sim:street'"),
        (lambda: open_sim(None), "spec: takes a 'sim:SCENE?key=value' string, got NoneType None"),
        (lambda: open_simcam(3), "spec: takes a 'simcam:SCENE?key=value' string, got int 3"),
        (lambda: export_bag(None, tmp_path / "q.bag", "rosbag1"), "sequence: takes a SimulatedLidarSequence, got NoneType None"),
        (lambda: export_kitti_images(None, tmp_path / "qq"), "sequence: takes a SimulatedCameraSequence, got NoneType None"),
    ]
    for call, message in calls:
        with pytest.raises(ConfigError) as err:
            call()
        assert str(err.value) == message
    assert not list(tmp_path.iterdir())


def test_hills_steeper_than_a_slope_of_one_half_are_refused_in_both_simulators():
    """terrain_amplitude_m=20 with terrain_wavelength_m=60, each within its own bound, made cliffs: the body tilted
    65 deg (seed 0). amplitude x 2 pi / wavelength is bounded at 0.5 (the body tilts at most 15-27 deg)."""
    from lidarkit.sim.street_camera import make_camera_config

    message = ("config: terrain_amplitude_m 20 m every terrain_wavelength_m 60 m makes slopes of 2.09 (amplitude x 2 pi / "
               "wavelength; at most 0.5, ~27 deg): a lower amplitude or a wavelength of at least 251 m")
    for make in (make_config, make_camera_config):
        with pytest.raises(ConfigError) as err:
            make(terrain_amplitude_m=20.0, terrain_wavelength_m=60.0)
        assert err.value.reason == message
    steepest = SimulatedLidarSequence(n_frames=300, n_beams=4, n_azimuths=64, terrain_amplitude_m=4.77, terrain_wavelength_m=60.0)
    tilt_deg = np.degrees(np.arccos(steepest.ground_truth.poses_se3[:, 2, 2]))
    assert 20.0 < tilt_deg.max() < 27.0


@pytest.mark.parametrize(("height", "heave", "lowest"), [(0.01, 0.02, "0.09"), (0.3, 0.5, "1.05")])
def test_a_sensor_the_heave_takes_below_the_ground_is_refused(height, heave, lowest):
    """sensor_height_m=0.01 (with the default 2 cm heave) or 0.3 with heave_m=0.5 put the sensor below the ground (z = -0.038
    over ground at -0.01) and sweeps returned the ground's underside: the heave lowers it by up to 2 x heave_m."""
    with pytest.raises(ConfigError) as err:
        make_config(sensor_height_m=height, heave_m=heave)
    assert str(err.value) == (f"lidar simulator: config: sensor_height_m {height:g} m with heave_m {heave:g} m can take the sensor "
                              f"below the ground (the heave lowers it by up to 2 x heave_m, and it must stay 0.05 m above the "
                              f"ground): sensor_height_m at least {lowest} m or a smaller heave_m")
    # the lowest height allowed keeps the sensor above the ground mesh, also on the steepest hills
    seq = SimulatedLidarSequence(scene="ground", n_frames=100, n_beams=4, n_azimuths=36, sensor_height_m=float(lowest),
                                 heave_m=heave, terrain_amplitude_m=4.77, terrain_wavelength_m=60.0)
    origins = seq.poses_at(np.linspace(0.0, 10.0, 2001))[:, :3, 3]
    down = np.c_[origins + [0.0, 0.0, 50.0], np.tile([0.0, 0.0, -1.0], (len(origins), 1))].astype(np.float32)
    clearance_m = seq.scene.cast_rays(o3d.core.Tensor(down))["t_hit"].numpy() - 50.0
    assert 0.02 < clearance_m.min() < float(lowest)  # (0.037 m for seed 0 at 0.09 m: the mesh lies up to 2 cm above the hills)


@pytest.mark.parametrize("scene", ["street", "open"])
def test_an_exports_sim_yaml_loads_back(tmp_path, scene):
    """The camera export's sim.yaml could not be loaded back (its default occluder fields were refused); the LiDAR
    one's loads back to the same config."""
    import yaml

    seq = SimulatedLidarSequence(scene=scene, n_beams=8, n_azimuths=180, n_frames=2, seed=3)
    written = yaml.safe_load((export_kitti(seq, tmp_path / "seq") / "sim.yaml").read_text())
    assert written.pop("note").startswith("poses are T_world_lidar")
    assert make_config(**written) == seq.config


@pytest.mark.parametrize(("field", "bound"), [("accel_time_s", "600"), ("sensor_height_m", "1000"), ("range_noise_std_m", "10")])
def test_huge_ramp_height_or_noise_is_refused_naming_the_field(field, bound):
    """1e308 was accepted: numpy overflow warnings, then an error blaming the sensor ("sweep 0 has no return")."""
    with pytest.raises(ConfigError) as err:
        make_config(**{field: 1e308})
    assert str(err.value) == f"lidar simulator: {field}: Input should be less than or equal to {bound}"
    assert getattr(make_config(**{field: float(bound)}), field) == float(bound)


def test_a_drive_beyond_the_float32_exact_reach_is_said(caplog):
    """The rays are cast in float32 world coordinates: 98 km out the sweeps lay 2.5 mm (median) off the surfaces their
    "exact" ground truth puts them on, without a word. A drive beyond 10 km says so; a shorter one does not."""
    import logging

    from lidarkit.sim.lidar import FLOAT32_EXACT_REACH_M

    with caplog.at_level(logging.WARNING, logger="lidarkit.sim.lidar"):
        SimulatedLidarSequence(n_frames=999, speed_mps=100, accel_time_s=0, n_beams=8, n_azimuths=64)  # 9.99 km
        assert caplog.text == ""
        SimulatedLidarSequence(n_frames=1001, speed_mps=100, accel_time_s=0, n_beams=8, n_azimuths=64)  # 10.01 km
    assert FLOAT32_EXACT_REACH_M == 10_000.0
    assert "the drive reaches 10 km from its start; the scene and rays are cast in float32 world coordinates" in caplog.text


def test_a_sweep_without_a_return_names_the_dataset_once_and_its_frame(tmp_path):
    """'sim:open?seed=4 (frame 8): sim:open?seed=4: sweep 8 has no return ...': the sweep's error named only the dataset,
    and the odometry runner placed it at its frame by naming the dataset again."""
    from lidarkit import odometry

    blind = SimulatedLidarSequence(scene="open", seed=1, n_frames=2, n_beams=4, n_azimuths=64, elevation_min_deg=1,
                                   elevation_max_deg=5, max_range_m=15)
    with pytest.raises(DataError) as read:
        blind.read_scan(1)
    assert (read.value.source, read.value.location) == ("sim:open?seed=1", "frame 1")
    assert str(read.value).startswith("sim:open?seed=1 (frame 1): sweep 1 has no return within 1-15 m: ")
    with pytest.raises(DataError) as run:
        odometry.run(blind, "kiss")
    assert str(run.value).startswith("sim:open?seed=1 (frame 0): sweep 0 has no return within 1-15 m: ")
    assert str(run.value).count("sim:open?seed=1") == 1


def test_a_sensor_too_low_without_heave_is_not_told_to_lower_its_heave():
    """sensor_height_m 0.04 with heave_m 0 was told "or a smaller heave_m", which cannot be smaller."""
    from lidarkit.sim.lidar import LidarSimConfig

    with pytest.raises(Exception) as exc:
        LidarSimConfig(sensor_height_m=0.04, heave_m=0.0)
    message = str(exc.value)
    assert "sensor_height_m 0.04 m is below the 0.05 m the sensor must stay above the ground" in message
    assert "or a smaller heave_m" not in message


def test_an_exports_times_read_back_as_the_simulators_stamps(tmp_path):
    """times.txt held 7 significant digits: at 7 Hz the stamps k / 7 read back up to 4.3e-5 s off over 3000 frames (and
    off in the last digits over any count). It holds the very float64 stamps now."""
    from lidarkit.io import open_dataset

    seq = SimulatedLidarSequence(scene="ground", n_beams=2, n_azimuths=8, n_frames=12, frame_rate_hz=7.0, pose_instant="mid")
    folder = open_dataset("kitti", export_kitti(seq, tmp_path / "seq"))
    np.testing.assert_array_equal(folder.timestamps_s, seq.timestamps_s)
    end = folder.ground_truth_at_instant("end")  # (moved by half the stamps' spacing: exact but for its rounding)
    np.testing.assert_allclose(end.timestamps_s, seq.ground_truth_at("end").timestamps_s, rtol=0, atol=1e-12)


def test_a_run_over_snapshot_sweeps_says_there_is_nothing_to_deskew(tmp_path):
    """motion_distortion=false (a spec, or its KITTI-layout export's sim.yaml): kiss warned "deskew requested, no
    per-point times found (looked for point_times/ ...): ran without deskew", as if data were missing. The sweeps are
    snapshots: the deskew reason says so, no warning, and --strict runs. Distorted sweeps exported without their times
    still warn."""
    from lidarkit.odometry import run

    snapshot_reason = "snapshot sweeps (motion_distortion false): nothing to deskew"
    small = dict(scene="street", n_frames=4, n_beams=16, n_azimuths=360, seed=1)
    snapshots = SimulatedLidarSequence(motion_distortion=False, **small)
    for data in (snapshots, export_kitti(snapshots, tmp_path / "snap")):
        result = run(data, "kiss")
        deskew = result.metrics["effective"]["deskew"]
        assert (deskew["requested"], deskew["applied"], deskew.get("needed"), deskew["reason"]) == (True, False, False, snapshot_reason)
        assert not [w for w in result.metrics["warnings"] if "deskew" in w], result.metrics["warnings"]
        assert run(data, "kiss", frames="0:2", strict=True).metrics["effective"]["deskew"]["reason"] == snapshot_reason
    timeless = run(export_kitti(SimulatedLidarSequence(point_times=False, **small), tmp_path / "timeless"), "kiss")
    assert timeless.metrics["effective"]["deskew"]["reason"].startswith("no per-point times found (looked for point_times/")
    assert any(w.startswith("deskew requested, no per-point times found") for w in timeless.metrics["warnings"])


def test_poses_at_refuses_a_time_that_is_not_a_finite_number_naming_times_s():
    """poses_at(np.array([np.nan])) gave a NaN pose, unsaid."""
    seq = SimulatedLidarSequence(**SMALL)
    for times, where in [(np.array([np.nan]), "time 0): time nan"), (np.array([0.05, np.inf]), "time 1): time inf")]:
        with pytest.raises(DataError) as err:
            seq.poses_at(times)
        assert str(err.value) == f"times_s ({where} is not a finite number (s)"
    assert np.isfinite(seq.poses_at(np.array([0.0, 0.05]))).all()


def test_poses_at_refuses_times_that_are_not_a_1d_array_of_numbers_naming_times_s():
    """poses_at(np.zeros((2, 2))) ended in a ValueError traceback, (3, 1) in an IndexError; text in a ValueError."""
    seq = SimulatedLidarSequence(**SMALL)
    for times, reason in [
        (np.zeros((2, 2)), "takes one time or a 1-D array of times, got shape (2, 2)"),
        (np.zeros((3, 1)), "takes one time or a 1-D array of times, got shape (3, 1)"),
        ("x", "takes times in seconds (numbers), got str 'x'"),
    ]:
        with pytest.raises(DataError) as err:
            seq.poses_at(times)
        assert str(err.value) == f"times_s: {reason}"
    assert seq.poses_at(0.05).shape == (1, 4, 4)
