"""Trajectory validation, KITTI/TUM round trips on real files, and evo conversion."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_path

from lidarkit.errors import ConfigError, DataError
from lidarkit.geometry import make_se3, random_se3, se3_inverse, so3_exp
from lidarkit.trajectory import Trajectory


def _random_trajectory(rng, n=20, with_time=True) -> Trajectory:
    poses = np.stack([random_se3(rng, 10.0) for _ in range(n)])
    ts = np.cumsum(rng.uniform(0.05, 0.15, size=n)) if with_time else None
    return Trajectory(poses, ts, name="random")


def test_kitti_real_file_and_round_trip(tmp_path):
    path = shared_path("evo_testdata", "KITTI_00_gt.txt")
    times = shared_path("evo_testdata", "KITTI_00_gt_times.txt")
    traj = Trajectory.from_kitti(path, timestamps_s=times)
    assert len(traj) == 4541
    np.testing.assert_allclose(traj.poses_se3[0], np.eye(4), atol=1e-6)
    assert traj.length_m == pytest.approx(3724.19, abs=0.5)  # KITTI 00 is ~3.7 km
    back = Trajectory.from_kitti(traj.to_kitti(tmp_path / "poses.txt"))
    np.testing.assert_allclose(back.poses_se3, traj.poses_se3, atol=1e-8)


def test_kitti_file_keeps_georeferenced_positions(tmp_path):
    """to_kitti wrote 10 significant digits: UTM positions (~5e6 m) came back up to 0.5 mm off (to_tum kept 1e-9 m)."""
    traj = Trajectory.from_tum(shared_path("evo_testdata", "georeferenced.tum"))
    assert np.abs(traj.positions_xyz).max() > 1e6
    back = Trajectory.from_kitti(traj.to_kitti(tmp_path / "poses.txt"))
    np.testing.assert_array_equal(back.positions_xyz, traj.positions_xyz)
    np.testing.assert_allclose(back.poses_se3, traj.poses_se3, rtol=0, atol=1e-15)
    # TUM stamps to 1e-9 s (6 decimals came back 0.48 us off: 1706282470.98386502 written as ...98387)
    tum = Trajectory.from_tum(traj.to_tum(tmp_path / "poses.tum"))
    assert np.abs(tum.timestamps_s - traj.timestamps_s).max() < 1e-8


def test_tum_real_file_and_round_trip(tmp_path):
    traj = Trajectory.from_tum(shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt"))
    assert len(traj) == 3000
    assert traj.timestamps_s[0] == pytest.approx(1305031098.6659, abs=1e-3)
    back = Trajectory.from_tum(traj.to_tum(tmp_path / "t.tum"))
    np.testing.assert_allclose(back.poses_se3, traj.poses_se3, atol=1e-8)
    np.testing.assert_allclose(back.timestamps_s, traj.timestamps_s, atol=1e-6)


def test_evo_round_trip_is_a_copy(rng):
    traj = _random_trajectory(rng)
    evo_traj = traj.to_evo()
    evo_traj.transform(make_se3(translation=[100.0, 0, 0]))  # evo works in place
    np.testing.assert_allclose(traj.positions_xyz, Trajectory.from_evo(traj.to_evo()).positions_xyz)
    assert not np.allclose(Trajectory.from_evo(evo_traj).positions_xyz, traj.positions_xyz)
    path_only = _random_trajectory(rng, with_time=False).to_evo()
    assert type(path_only).__name__ == "PosePath3D"


def test_relative_motions_chain_back(rng):
    traj = _random_trajectory(rng)
    rebuilt = Trajectory.from_relative_motions(traj.relative_motions(), traj.poses_se3[0], traj.timestamps_s)
    np.testing.assert_allclose(rebuilt.poses_se3, traj.poses_se3, atol=1e-9)
    rel = traj.relative_to_first()
    np.testing.assert_allclose(rel.poses_se3[0], np.eye(4), atol=1e-12)


def test_transformed_changes_frame(rng):
    traj = _random_trajectory(rng, n=5)
    Tr = random_se3(rng, 1.0)
    moved = traj.transformed(se3_inverse(Tr), Tr)
    np.testing.assert_allclose(moved.poses_se3, se3_inverse(Tr) @ traj.poses_se3 @ Tr, atol=1e-12)


def test_rounded_rotations_accepted_and_bad_ones_refused():
    R = so3_exp([0.1, 0.2, 0.3])
    ok = make_se3(np.round(R, 7))
    Trajectory(np.stack([ok, ok]))
    bad = make_se3(R * 1.01)
    with pytest.raises(DataError, match="frame 1.*not orthonormal"):
        Trajectory(np.stack([ok, bad]), name="est")


@pytest.mark.parametrize(
    "poses, ts, match",
    [
        (np.zeros((3, 3, 3)), None, r"shape \(N, 4, 4\)"),
        (np.stack([np.eye(4), np.full((4, 4), np.nan)]), None, "frame 1.*NaN"),
        (np.stack([np.eye(4)] * 3), [0.0, 1.0], "2 timestamps for 3 poses"),
        (np.stack([np.eye(4)] * 3), [0.0, 2.0, 1.0], "frame 2.*not strictly increasing"),
    ],
)
def test_invalid_trajectories(poses, ts, match):
    with pytest.raises(DataError, match=match):
        Trajectory(poses, ts)


def test_malformed_files_name_file_and_line(tmp_path):
    kitti = tmp_path / "bad.txt"
    kitti.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n")
    with pytest.raises(DataError, match=r"bad.txt \(line 2\): expected 12 numbers, found 11"):
        Trajectory.from_kitti(kitti)
    kitti.write_text("1 0 0 0 0 1 0 0 0 0 1 x\n")
    with pytest.raises(DataError, match=r"line 1\): not a number: 'x'"):
        Trajectory.from_kitti(kitti)
    tum = tmp_path / "bad.tum"
    tum.write_text("# c\n0 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 5\n")
    with pytest.raises(DataError, match=r"line 3, frame 1\): quaternion norm"):
        Trajectory.from_tum(tum)
    with pytest.raises(DataError, match="file not found"):
        Trajectory.from_kitti(tmp_path / "missing.txt")
    with pytest.raises(ConfigError, match="unknown trajectory format 'csv'"):
        Trajectory.read(kitti, fmt="csv")


def test_times_count_mismatch(tmp_path):
    poses = tmp_path / "p.txt"
    Trajectory(np.stack([np.eye(4)] * 3)).to_kitti(poses)
    times = tmp_path / "times.txt"
    times.write_text("0.0\n0.1\n")
    with pytest.raises(DataError, match="2 timestamps for 3 poses"):
        Trajectory.from_kitti(poses, timestamps_s=times)


def test_interpolated_poses_between_and_just_beyond_the_stamps():
    """A constant twist (yaw rate and velocity): slerp + linear position reproduce it exactly between the stamps,
    and at constant velocity up to max_extrapolation_s beyond them; farther is a DataError naming the time."""
    from scipy.spatial.transform import Rotation

    from lidarkit.errors import DataError

    def truth(t):
        T = np.tile(np.eye(4), (len(t), 1, 1))
        T[:, :3, :3] = Rotation.from_euler("z", 0.3 * t[:, None]).as_matrix()
        T[:, :3, 3] = np.column_stack([2.0 * t, -0.5 * t, 0.1 * t])
        return T

    stamps = np.array([0.0, 0.1, 0.25, 0.4])
    traj = Trajectory(truth(stamps), stamps, name="gt", meta={"pose_instant": "end"})
    times = np.array([-0.05, 0.0, 0.07, 0.1, 0.3, 0.4, 0.5])
    out = traj.interpolated(times, max_extrapolation_s=0.1)
    np.testing.assert_allclose(out.poses_se3, truth(times), atol=1e-12)
    np.testing.assert_array_equal(out.timestamps_s, times)
    assert out.meta == {"pose_instant": "end"} and out.name == "gt"
    with pytest.raises(DataError, match=r"\(time 1\): time 0\.6 s lies 0\.200 s outside the stamps"):
        traj.interpolated(np.array([0.3, 0.6]), max_extrapolation_s=0.1)
    with pytest.raises(DataError, match=r"\(time 1\): time nan is not a finite number"):
        traj.interpolated(np.array([0.3, np.nan]))
    assert len(traj.interpolated(np.array([]))) == 0
    with pytest.raises(DataError, match="two poses with time stamps"):
        Trajectory(truth(stamps)).interpolated(times)



def test_interpolation_times_and_bound_of_the_wrong_kind_are_named():
    """Times asked out of order read "gt (frame 1): timestamps are not strictly increasing", blaming the trajectory;
    a bound of None or text was a bare TypeError, times of text numpy's ValueError."""
    from lidarkit.errors import ConfigError

    traj = Trajectory(np.tile(np.eye(4), (3, 1, 1)), np.array([0.0, 1.0, 2.0]), name="gt")
    for times in ([1.0, 0.5], [0.5, 0.5]):
        with pytest.raises(ConfigError, match=r"^times_s: times_s must be strictly increasing: time 1 \(0\.5 s\) "
                                              r"is not after time 0"):
            traj.interpolated(times)
    for bound in (None, "0.1", -1.0, True):
        with pytest.raises(ConfigError, match=r"^max_extrapolation_s: max_extrapolation_s must be a number of seconds >= 0"):
            traj.interpolated([0.5], max_extrapolation_s=bound)
    with pytest.raises(ConfigError, match=r"^times_s: times_s must be numbers \(s\), got 'abc'"):
        traj.interpolated("abc")
    assert traj.interpolated([0.5, 1.5], max_extrapolation_s=np.float64(0.0)).timestamps_s.tolist() == [0.5, 1.5]


def test_interpolation_times_of_none_are_refused_as_not_numbers():
    """interpolated(None) read None as NaN: "DataError trajectory (time 0): time nan is not a finite number", blaming
    the trajectory for the caller's argument; now the ConfigError of times that are not numbers, as for 'abc'."""
    from lidarkit.errors import ConfigError

    traj = Trajectory(np.tile(np.eye(4), (3, 1, 1)), [0, 1, 2])
    for times, shown in ((None, "None"), ([0.5, None], "[0.5, None]")):
        with pytest.raises(ConfigError) as err:
            traj.interpolated(times)
        assert str(err.value) == f"times_s: times_s must be numbers (s), got {shown}"
    assert traj.interpolated(np.array([0.5, 1.5], dtype=np.float32)).timestamps_s.tolist() == [0.5, 1.5]


def test_reprs_are_one_line_and_an_empty_trajectory_has_no_distances():
    """repr(Trajectory) printed every pose (7,200 characters for 20) and repr(OdometryResult) every array (57,000);
    an empty trajectory's distances_m had one entry."""
    from lidarkit.odometry import run

    result = run("sim:street?frames=4&beams=8&azimuths=180", "vanilla", progress=False)
    assert repr(result).startswith("OdometryResult('vanilla', 4 frames in ") and "end error" in repr(result) and "\n" not in repr(result)
    # (repr(result.stats) printed every per-frame array: 11,600 characters for 60 frames)
    stats = result.stats
    assert repr(stats) == (f"FrameStats(4 frames: {int(stats.fallback.sum())} fallback, {int((stats.degenerate & stats.measured).sum())} "
                           f"degenerate, {int(stats.check_failed.sum())} failing the check, registration "
                           f"{stats.register_s[1:].mean():.3g} s a frame; to_csv() for every frame)")
    # (stamped at the sweep middles, where a non-deskewed estimate refers to: the scans' sweep-end stamps less 0.05 s)
    assert repr(result.trajectory) == (f"Trajectory('vanilla on sim:street?seed=0', 4 poses, 0.05-0.35 s (0.3 s), "
                                       f"path {result.trajectory.length_m:.4g} m)")
    tum = Trajectory.from_tum(shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt"))
    assert "3000 poses, 1305031098.6659-1305031128.7555 s (30.09 s)" in repr(tum)  # (read "1.30503e+09-1.30503e+09 s")
    with pytest.raises(ConfigError, match=r"T_left: T_left must be a 4x4 transform, got shape \(3, 3\)"):
        tum.transformed(np.eye(3))
    empty = Trajectory(np.zeros((0, 4, 4)))
    assert empty.distances_m.shape == (0,) and empty.length_m == 0.0
    assert repr(empty) == "Trajectory('', 0 poses, no stamps, path 0 m)"
    from lidarkit.io import open_dataset
    from lidarkit.sim.lidar import SimulatedLidarSequence

    assert repr(SimulatedLidarSequence(n_frames=3, n_beams=8, n_azimuths=90)) == "SimulatedLidarSequence('sim:street?seed=0', 3 sweeps of 8x90 rays)"
    aces = shared_path("carmen_2d", "aces.clf.bz2")
    assert repr(open_dataset("carmen", aces)) == f"CarmenLog({str(aces)!r}, 7374 scans)"  # (<... object at 0x...> before)


def test_chaining_a_real_trajectorys_own_motions_gives_it_back():
    """KITTI 00's ground truth chained from its own relative motions was refused at frame 481 ("rotation is not
    orthonormal"): the file's rounding, accumulated. Each chained pose is re-orthonormalized once it drifts."""
    gt = Trajectory.from_kitti(shared_path("evo_testdata", "KITTI_00_gt.txt"))
    chained = Trajectory.from_relative_motions(gt.relative_motions())
    assert len(chained) == len(gt) and np.abs(chained.positions_xyz - gt.positions_xyz).max() < 1e-3


def test_wrong_kinds_of_arguments_are_one_line_errors(tmp_path):
    """A file name given to align() read "got shape ()"; open_dataset(kind, None), read_scan(1.5) and
    evaluate(settings={...}) were TypeErrors, IndexErrors or AttributeErrors from inside."""
    from lidarkit.eval import evaluate
    from lidarkit.io import open_dataset
    from lidarkit.registration import get_icp

    with pytest.raises(DataError, match="source cloud: expected an \\(N, 3\\) point array, got str 'a.bin'"):
        get_icp("vanilla").align("a.bin", np.zeros((5, 3)))
    for path in (None, 5):
        with pytest.raises(ConfigError, match=f"kitti dataset: the dataset path must be a path, got {type(path).__name__}"):
            open_dataset("kitti", path)
    kitti = open_dataset("kitti", shared_path("kitti_odometry", "sequences", "00"))
    for index in (1.5, "1", True):
        with pytest.raises(DataError, match=f"scan index {index!r} is not an integer"):
            kitti.read_scan(index)
    assert kitti.read_scan(np.int64(1)).frame == 1
    gt = Trajectory.from_kitti(shared_path("evo_testdata", "KITTI_00_gt.txt"))[:50]
    with pytest.raises(ConfigError, match="evaluate: settings must be an EvaluationSettings .*, got dict"):
        evaluate(gt, gt, settings={"align": "none"})


def test_a_cut_off_kitti_file_is_not_called_a_tum_trajectory(tmp_path):
    """A KITTI pose file cut off in line 19 read "(a TUM trajectory? ...)" after 18 full rows; only a file whose first
    row has TUM's 8 numbers gets the hint."""
    text = shared_path("evo_testdata", "KITTI_00_gt.txt").read_text()
    (tmp_path / "cut.txt").write_text(text[:3000])
    with pytest.raises(DataError) as err:
        Trajectory.from_kitti(tmp_path / "cut.txt")
    assert str(err.value).endswith("(line 19): expected 12 numbers, found 8")
    with pytest.raises(DataError, match=r"\(a TUM trajectory\? read it as tum"):
        Trajectory.from_kitti(shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt"))


def test_a_kitti_file_read_as_tum_is_hinted(tmp_path):
    """`eval KITTI_00_gt.txt KITTI_00_ORB.txt --format tum` read "(line 1): expected 8 numbers, found 12" with no hint
    (the reverse mistake had one): a file whose first row has KITTI's 12 numbers now says so; a later such row does not."""
    gt = shared_path("evo_testdata", "KITTI_00_gt.txt")
    with pytest.raises(DataError) as err:
        Trajectory.from_tum(gt)
    assert str(err.value) == (f"{gt} (line 1): expected 8 numbers, found 12 "
                              "(a KITTI trajectory? read it as kitti: --format kitti, Trajectory.from_kitti)")
    tum = shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt").read_text().splitlines()
    (tmp_path / "mixed.txt").write_text("\n".join(tum[:10]) + "\n" + gt.read_text().splitlines()[0] + "\n")
    with pytest.raises(DataError) as err:
        Trajectory.from_tum(tmp_path / "mixed.txt")
    assert str(err.value).endswith("mixed.txt (line 11): expected 8 numbers, found 12")


def test_a_caller_names_its_own_format_option_in_the_hint():
    """Readers that choose the format by another option (a scan folder's ``poses_format=``, vo's ``--poses-format``)
    rewrote the fixed "--format tum, Trajectory.from_tum" by string replacement; ``format_hint`` names it directly,
    through ``Trajectory.read`` too, and is no format option in read's listing."""
    gt, tum = shared_path("evo_testdata", "KITTI_00_gt.txt"), shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt")
    hint = lambda other: f"fmt={other!r}"  # noqa: E731
    with pytest.raises(DataError) as err:
        Trajectory.read(gt, "tum", format_hint=hint)
    assert str(err.value).endswith("(a KITTI trajectory? read it as kitti: fmt='kitti')")
    with pytest.raises(DataError) as err:
        Trajectory.from_kitti(tum, format_hint=hint)
    assert str(err.value).endswith("(a TUM trajectory? read it as tum: fmt='tum')")
    with pytest.raises(ConfigError) as err:
        Trajectory.read(tum, "tum", stamps=1, format_hint=hint)
    assert str(err.value) == "stamps: stamps is no option of the tum format (tum options: name)"

def test_relative_motions_must_be_rigid_and_extrapolation_non_negative():
    """from_relative_motions chained all-zero motions into identity poses and dropped a Sim(3) motion's scale (the
    constructor refuses both poses); NaN motions were an SVD traceback; interpolated(max_extrapolation_s=-1) refused a
    time inside the stamps as "-0.500 s outside"."""
    from lidarkit.errors import ConfigError

    scaled = np.tile(np.diag([1.1, 1.1, 1.1, 1.0]), (3, 1, 1))
    nan = np.tile(np.eye(4), (3, 1, 1))
    nan[2, 0, 3] = np.nan
    for motions, reason in ((np.zeros((3, 4, 4)), r"\(motion 0\): last row of the pose is not \[0, 0, 0, 1\]"),
                            (scaled, r"\(motion 0\): rotation is not orthonormal"),
                            (nan, r"\(motion 2\): pose is NaN or infinite")):
        with pytest.raises(DataError, match=r"^odo: relative motions " + reason):
            Trajectory.from_relative_motions(motions, name="odo")
    steps = np.tile(make_se3(translation=[1.0, 0.0, 0.0]), (3, 1, 1))
    assert Trajectory.from_relative_motions(steps).poses_se3[-1, 0, 3] == 3.0
    two = Trajectory(np.tile(np.eye(4), (2, 1, 1)), np.array([0.0, 1.0]), name="t")
    with pytest.raises(ConfigError, match=r"^max_extrapolation_s: max_extrapolation_s must be a number of seconds >= 0, got -1"):
        two.interpolated(np.array([0.5]), max_extrapolation_s=-1)
    assert len(two.interpolated(np.array([0.5, 1.2]), max_extrapolation_s=0.5)) == 2


def test_a_tum_file_whose_stamps_lost_their_digits_is_refused(tmp_path):
    """fr1_xyz's ground truth written with %.1f stamps: 2698 of 3000 poses repeat a stamp; each was left out with a
    warning and the 10 % left were scored (APE 0.0227 m where evo says 0.0143)."""
    gt = np.loadtxt(shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt"))
    coarse = tmp_path / "gt_1f.txt"
    np.savetxt(coarse, np.column_stack([np.round(gt[:, 0], 1), gt[:, 1:]]), fmt=["%.1f"] + ["%.6f"] * 7)
    n_repeated = int((np.diff(np.round(gt[:, 0], 1)) == 0).sum())
    with pytest.raises(DataError, match=rf"gt_1f.txt: {n_repeated} of {len(gt)} poses repeat the timestamp .*too few decimals"):
        Trajectory.from_tum(coarse)
    assert len(Trajectory.from_tum(shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt"))) == len(gt)


def test_transform_arguments_must_be_rigid():
    """transformed() and from_relative_motions() checked only the shape of T_left / T_right / T_first: a scaled, a
    2*eye(4) or a NaN one was blamed on the trajectory's own "(frame 0)" as a DataError advising to write a file with
    more digits."""
    gt = Trajectory.from_kitti(shared_path("evo_testdata", "KITTI_00_gt.txt"))
    nan = np.eye(4)
    nan[0, 3] = np.nan
    for kwargs, message in (
        (dict(T_left=np.diag([2.0, 2.0, 2.0, 1.0])), "T_left: T_left is not a rigid transform: its 3x3 block is no rotation "
                                                       "(R^T R = I within 0.0001, det R > 0; a scale is not rigid)"),
        (dict(T_left=2 * np.eye(4)), "T_left: T_left is not a rigid transform: its last row is [0.0, 0.0, 0.0, 2.0], not [0, 0, 0, 1]"),
        (dict(T_right=nan), "T_right: T_right is not a rigid transform: it has NaN or infinite entries"),
    ):
        with pytest.raises(ConfigError) as err:
            gt.transformed(**kwargs)
        assert str(err.value) == message
    motions = gt.relative_motions()[:5]
    with pytest.raises(ConfigError) as err:
        Trajectory.from_relative_motions(motions, T_first=2 * np.eye(4))
    assert str(err.value) == "T_first: T_first is not a rigid transform: its last row is [0.0, 0.0, 0.0, 2.0], not [0, 0, 0, 1]"
    Tr = make_se3(so3_exp(np.array([0.1, -0.2, 0.3])), np.array([1.0, 2.0, 3.0]))
    moved = gt.transformed(T_left=Tr)
    np.testing.assert_allclose(moved.poses_se3[10], Tr @ gt.poses_se3[10], atol=1e-12)


def test_relative_motions_shapes_are_checked():
    """from_relative_motions(T_first=np.eye(3)) was numpy's broadcast ValueError, (n, 3, 3) motions "cannot reshape
    array of size 27 into shape (4,4)", and a flat array of 48 numbers was silently taken as 3 motions."""
    with pytest.raises(ConfigError) as err:
        Trajectory.from_relative_motions(np.tile(np.eye(4), (3, 1, 1)), T_first=np.eye(3))
    assert str(err.value) == "T_first: T_first must be a 4x4 transform, got shape (3, 3)"
    for motions, shape in ((np.tile(np.eye(3), (3, 1, 1)), "(3, 3, 3)"), (np.tile(np.eye(4), (3, 1, 1)).reshape(-1), "(48,)")):
        with pytest.raises(ConfigError) as err:
            Trajectory.from_relative_motions(motions)
        assert str(err.value) == f"motions: motions must have shape (n, 4, 4), got {shape}"
    one = Trajectory(make_se3(translation=[1.0, 2.0, 3.0])[None])
    rebuilt = Trajectory.from_relative_motions(one.relative_motions(), T_first=one.poses_se3[0])
    assert len(rebuilt) == 1 and rebuilt.poses_se3[0, 2, 3] == 3.0


def test_read_refuses_an_option_of_the_other_format():
    """Trajectory.read(path, fmt="tum", timestamps_s=...) was a TypeError "unexpected keyword argument" from from_tum."""
    tum = shared_path("evo_testdata", "freiburg1_xyz-groundtruth.txt")
    with pytest.raises(ConfigError) as err:
        Trajectory.read(tum, fmt="tum", timestamps_s=None)
    assert str(err.value) == "timestamps_s: timestamps_s applies to the kitti format, not tum (tum options: name)"
    with pytest.raises(ConfigError) as err:
        Trajectory.read(tum, fmt="kitti", stamps=None)
    assert str(err.value) == "stamps: stamps is no option of the kitti format (kitti options: timestamps_s, name)"
    assert len(Trajectory.read(tum, fmt="tum", name="fr1")) == 3000


def test_an_empty_trajectory_is_not_written_since_no_reader_takes_the_file_back(tmp_path):
    """to_kitti / to_tum wrote a file of no rows (TUM: its header alone) that from_kitti / from_tum then refused with
    "no data rows": the write is refused instead, naming the path, and a file already there is left as it was."""
    kept = tmp_path / "kept.txt"
    kept.write_text("old\n")
    for empty in (Trajectory(np.zeros((0, 4, 4))), Trajectory(np.zeros((0, 4, 4)), np.zeros(0))):
        for write, path in ((empty.to_kitti, tmp_path / "e.kitti"), (empty.to_tum, tmp_path / "e.tum"),
                            (lambda p: empty.write(p, "tum"), kept)):
            with pytest.raises(DataError) as err:
                write(path)
            assert str(err.value) == f"{path}: an empty trajectory (0 poses) is not written: the readers refuse empty files"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.txt"] and kept.read_text() == "old\n"
    one = Trajectory(make_se3(translation=[1.0, 2.0, 3.0])[None], [5.0])  # (one pose is written and read back)
    assert Trajectory.from_kitti(one.to_kitti(tmp_path / "one.kitti")).poses_se3[0, 2, 3] == 3.0
    assert Trajectory.from_tum(one.to_tum(tmp_path / "one.tum")).timestamps_s.tolist() == [5.0]


def test_stamps_beyond_any_time_in_seconds_are_refused_where_files_are_read(tmp_path):
    """A TUM file or a times file in nanoseconds (EuRoC's 1.4e18) was read as seconds without a word: the per-speed table
    put every segment in "0-5 m/s" and --associate's 0.01 s window paired only identical stamps. Stamps beyond 1e11 s
    (after the year 5000) are refused at their line; seconds since 1970 are read as before."""
    n = 5
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = np.arange(n)
    seconds = 1403715529.1 + 0.1 * np.arange(n)
    Trajectory(poses, seconds).to_tum(tmp_path / "seconds.tum")
    np.testing.assert_allclose(Trajectory.from_tum(tmp_path / "seconds.tum").timestamps_s, seconds)
    rows = np.loadtxt(tmp_path / "seconds.tum")
    for unit, factor in (("ns", 10**9), ("us", 10**6), ("ms", 10**3)):
        lines = ["# timestamp tx ty tz qx qy qz qw"]
        lines += [" ".join([str(round(row[0] * factor)), *(f"{v:.9f}" for v in row[1:])]) for row in rows]
        (tmp_path / f"{unit}.tum").write_text("\n".join(lines) + "\n")
        first = lines[1].split()[0]
        with pytest.raises(DataError, match=rf"^\S*{unit}.tum \(line 2, frame 0\): time stamp {first} is beyond 1e\+11 s "
                                            r"\(after the year 5000\): they look like nanoseconds \(or micro/milliseconds\): "
                                            r"write seconds, e.g. divide by 1e9$"):
            Trajectory.from_tum(tmp_path / f"{unit}.tum")
    Trajectory(poses).to_kitti(tmp_path / "poses.txt")
    (tmp_path / "times.txt").write_text("0.0\n0.1\n0.2\n1403715529300000000\n0.4\n")
    with pytest.raises(DataError, match=r"^\S*times.txt \(line 4, frame 3\): time stamp 1403715529300000000 is beyond 1e\+11 s"):
        Trajectory.from_kitti(tmp_path / "poses.txt", tmp_path / "times.txt")
    # (stamps given as an array are the caller's, in seconds: not a file's text)
    assert Trajectory.from_kitti(tmp_path / "poses.txt", seconds).timestamps_s[0] == seconds[0]
