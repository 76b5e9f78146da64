"""``kiss``: the KISS-ICP reference (Vizzo et al., RA-L 2023) through the ``kiss_icp`` package.

Sequence mode (:meth:`KissRegistration.register_frame`) drives ``kiss_icp.kiss_icp.KissICP`` with the
``KISSConfig`` built by :meth:`KissConfig.to_kiss_config`, so poses are bit-identical to calling
KissICP directly: adaptive threshold, constant-velocity deskew (when per-point times are given,
to the END of the sweep, as kiss-icp 1.3 does) and the voxel-hash local map.
Pairwise mode (:meth:`align`) builds the local map from the target alone and registers the
voxelized source with ``init_T`` and the initial (or fixed) threshold. kiss-icp does not say whether it stopped on
its criterion or at ``max_num_iterations``: below kiss-icp's own cap (500), where hitting it is likely, one more
iteration from the returned pose (:func:`still_moving`) decides ``converged``; at 500 or more the verdict is the
library's (True).

kiss-icp aborts the whole process ("R is not orthogonal", Sophus) when handed a rotation that is not
orthonormal to ~1e-10, e.g. one read back from a text file: every pose lidarkit passes to it goes
through :func:`kiss_safe_pose`.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field, model_validator

from lidarkit.errors import RegistrationError
from lidarkit.geometry import as_points, is_rotation, orthonormalize_se3, se3_fraction, se3_inverse, se3_log
from lidarkit.params import changed_fields
from lidarkit.registration import local_origin
from lidarkit.registration.assessment import assess_alignment
from lidarkit.registration.base import (
    Registration, RegistrationConfig, RegistrationResult, check_init_T, check_point_times, check_sweeps_apart, finite_4x4,
)
from lidarkit.registration.registry import register_icp

#: Rotations passed to kiss-icp must be orthonormal to this (Sophus checks ~1e-10).
KISS_ORTHONORMAL_TOL = 1e-12


def kiss_safe_pose(T: np.ndarray, name: str = "pose") -> np.ndarray:
    """A float64 4x4 pose kiss-icp accepts: re-orthonormalized unless already exact (then returned as is)."""
    T = finite_4x4(T, name, "pose")
    if is_rotation(T[:3, :3], tol=KISS_ORTHONORMAL_TOL) and np.array_equal(T[3], [0.0, 0.0, 0.0, 1.0]):
        return T
    return orthonormalize_se3(T)


def still_moving(registration_config, points: np.ndarray, voxel_map, T: np.ndarray, max_distance_m: float,
                 kernel_sigma_m: float) -> float | None:
    """The norm of the step kiss-icp takes from ``T`` in one more iteration when it exceeds ``convergence_criterion``
    (kiss-icp stopped at its iteration cap, not converged), else None: kiss-icp does not return its iteration count.
    ``registration_config``: the ``KISSConfig.registration`` the alignment ran with."""
    from kiss_icp.registration import Registration as KissIcpRegistration

    one_step = KissIcpRegistration(max_num_iterations=1, convergence_criterion=registration_config.convergence_criterion,
                                   max_num_threads=registration_config.max_num_threads)
    moved = one_step.align_points_to_map(points=points, voxel_map=voxel_map, initial_guess=kiss_safe_pose(T, "pose"),
                                         max_correspondance_distance=max_distance_m, kernel=kernel_sigma_m)
    step = float(np.linalg.norm(se3_log(np.asarray(moved, dtype=np.float64) @ se3_inverse(T))))
    return step if step >= registration_config.convergence_criterion else None


class KissConfig(RegistrationConfig):
    """KISS-ICP parameters (flattened ``KISSConfig``; defaults are kiss-icp 1.3's)."""

    max_range_m: float = Field(100.0, gt=0, description="drop points farther than this (m)")
    min_range_m: float = Field(0.0, ge=0, description="drop points closer than this (m)")
    deskew: bool = Field(True, description="constant-velocity motion compensation when per-point times exist")
    voxel_size_m: float | None = Field(None, gt=0, description="map voxel size (m); None: max_range_m / 100")
    max_points_per_voxel: int = Field(20, ge=1, description="points kept per map voxel")
    max_num_iterations: int = Field(500, ge=1, description="ICP iterations per frame")
    convergence_criterion: float = Field(1e-4, gt=0, description="stop when the update norm is below this")
    max_num_threads: int = Field(0, ge=0, description="threads (0: automatic)")
    fixed_threshold_m: float | None = Field(None, gt=0, description="fixed correspondence threshold sigma (m); None: adaptive")
    initial_threshold_m: float = Field(2.0, gt=0, description="adaptive threshold before enough motion (m)")
    min_motion_th_m: float = Field(0.1, ge=0, description="motion below this does not update the adaptive threshold (m)")

    @model_validator(mode="after")
    def _ranges(self) -> "KissConfig":
        if self.max_range_m <= self.min_range_m:
            raise ValueError(f"max_range_m ({self.max_range_m}) must exceed min_range_m ({self.min_range_m})")
        if self.fixed_threshold_m is not None and changed_fields(self, ("initial_threshold_m", "min_motion_th_m")):
            raise ValueError("initial_threshold_m / min_motion_th_m set the adaptive threshold, which fixed_threshold_m replaces")
        return self

    @property
    def resolved_voxel_size_m(self) -> float:
        return self.voxel_size_m if self.voxel_size_m is not None else self.max_range_m / 100.0

    def to_kiss_config(self):
        """The equivalent ``kiss_icp.config.KISSConfig`` (voxel size resolved as kiss-icp's load_config does)."""
        from kiss_icp.config.config import AdaptiveThresholdConfig, DataConfig, MappingConfig
        from kiss_icp.config.config import RegistrationConfig as KissRegistrationConfig
        from kiss_icp.config.parser import KISSConfig

        return KISSConfig(
            data=DataConfig(max_range=self.max_range_m, min_range=self.min_range_m, deskew=self.deskew),
            mapping=MappingConfig(voxel_size=self.resolved_voxel_size_m, max_points_per_voxel=self.max_points_per_voxel),
            registration=KissRegistrationConfig(
                max_num_iterations=self.max_num_iterations,
                convergence_criterion=self.convergence_criterion,
                max_num_threads=self.max_num_threads,
            ),
            adaptive_threshold=AdaptiveThresholdConfig(
                fixed_threshold=self.fixed_threshold_m,
                initial_threshold=self.initial_threshold_m,
                min_motion_th=self.min_motion_th_m,
            ),
        )


class _OneSweepDeskew:
    """kiss-icp's preprocessor deskewing with ``delta`` scaled to one sweep: ``exp(log(delta) / sweeps)`` (kiss-icp's
    register_frame hands its preprocessor the motion since the last frame, and reads that motion itself for its guess)."""

    def __init__(self, preprocessor, sweeps: float):
        self.preprocessor, self.sweeps = preprocessor, float(sweeps)

    def preprocess(self, frame, timestamps, delta):
        one_sweep = kiss_safe_pose(se3_fraction(np.asarray(delta, dtype=np.float64), self.sweeps), "deskew motion")
        return self.preprocessor.preprocess(frame, timestamps, one_sweep)


@register_icp("kiss")
class KissRegistration(Registration):
    """KISS-ICP: stateful odometry (``register_frame``) or pairwise scan-to-map alignment (``align``)."""

    Config = KissConfig
    stateful = True
    # kiss-icp's registration and map update hold the GIL through most of their C++ work
    # (benchmarks/results/icp/gil_probe.md): a frame's covariance in a worker thread only waits for it (300 simulated
    # 32 x 360 sweeps: 0.78x kiss-icp's pipeline overlapped, 0.81x in line); the frame check's queries, which release
    # the GIL, get a thread of the check's own (FrameChecker overlap)
    overlap_assessment = False
    #: ``register_frame`` takes ``motion_guess`` (e.g. wheel odometry) instead of kiss-icp's constant velocity
    accepts_motion_guess = True
    #: ``register_frame`` takes ``sweeps_apart`` (frames that skip sweeps: its deskew motion is scaled to one sweep)
    accepts_sweeps_apart = True

    def __init__(self, config: KissConfig | None = None, **params):
        super().__init__(config, **params)
        self._kiss = None
        self._delta_sweeps = 1.0  # sweeps spanned by last_delta (the previous frame's sweeps_apart)

    @property
    def deskew_instant(self) -> str | None:
        """The instant of the sweep deskewed poses refer to: kiss-icp 1.x deskews to the latest point (the END)."""
        return "end" if self.config.deskew else None

    @property
    def kiss_config(self):
        """The ``kiss_icp`` KISSConfig this wrapper runs with (a fresh object each call)."""
        return self.config.to_kiss_config()

    @property
    def pipeline(self):
        """The underlying ``kiss_icp.kiss_icp.KissICP`` (created on first use)."""
        if self._kiss is None:
            self.reset()
        return self._kiss

    def reset(self, T_world_lidar_initial: np.ndarray | None = None) -> None:
        """Start a new sequence: empty map, zero velocity, first pose ``T_world_lidar_initial`` (identity), checked as
        ``align``'s ``init_T`` (a reflection or a scaled matrix was re-orthonormalized into another pose)."""
        from kiss_icp.kiss_icp import KissICP

        start = None if T_world_lidar_initial is None else check_init_T(T_world_lidar_initial, "T_world_lidar_initial")
        self._kiss = KissICP(self.kiss_config)
        self._delta_sweeps = 1.0
        if start is not None:
            self._kiss.last_pose = kiss_safe_pose(start, "T_world_lidar_initial")

    def register_frame(
        self, points_xyz: np.ndarray, point_times_s: np.ndarray | None = None, motion_guess: np.ndarray | None = None,
        sweeps_apart: float = 1.0,
    ) -> np.ndarray:
        """Register one sweep; returns ``T_world_lidar`` (4x4) of this frame (at the end of the sweep when deskewed).

        ``motion_guess``: the previous-to-this-frame motion to start from (and deskew with), e.g. from wheel
        odometry, in place of kiss-icp's constant-velocity prediction (``last_delta``); checked as ``align``'s
        ``init_T`` (a reflection or a scaled matrix was re-orthonormalized into another motion).
        ``sweeps_apart``: sweeps between the previous frame and this one (frames that skip scans). kiss-icp deskews
        with the motion between registered frames as one sweep's: N sweeps apart, the correction was N times too
        large (worse than none). The deskew then takes that motion scaled to one sweep; the initial guess the whole.
        kiss-icp's constant-velocity guess (``last_delta``, the motion over the previous frame's sweeps) is taken at
        its rate over this frame's sweeps: after a gap of dropped scans it predicted one sweep's motion (6.6 m off
        across 8 sweeps on a simulated street), and the frame after the gap the gap's.
        """
        kiss = self.pipeline
        frame = np.ascontiguousarray(as_points(points_xyz, "frame", min_points=1))
        if point_times_s is None:
            times = np.array([])
        else:
            times = check_point_times(point_times_s, len(frame))
            if np.ptp(times) <= 0.0:  # all equal: kiss-icp would divide by their zero span and abort the process
                times = np.array([])
        kiss.last_pose = kiss_safe_pose(kiss.last_pose, "last_pose")
        sweeps_apart = check_sweeps_apart(sweeps_apart)
        if motion_guess is None:  # the previous motion at its rate (the same array for as many sweeps as before)
            delta = se3_fraction(kiss.last_delta, self._delta_sweeps / sweeps_apart)
        else:
            delta = check_init_T(motion_guess, "motion_guess")
        kiss.last_delta = kiss_safe_pose(delta, "last_delta")
        spans = sweeps_apart  # the sweeps the deskew motion (last_delta) spans
        self._delta_sweeps = sweeps_apart
        if spans == 1.0 or len(times) == 0 or not self.config.deskew:
            _, source = kiss.register_frame(frame, times)
        else:
            kiss.preprocessor, own = _OneSweepDeskew(kiss.preprocessor, spans), kiss.preprocessor
            try:
                _, source = kiss.register_frame(frame, times)
            finally:
                kiss.preprocessor = own
        if len(source) == 0 and kiss.local_map.empty():  # nothing registered yet and nothing to register with
            c = self.config
            within = local_origin.range_crop_text(c.min_range_m, c.max_range_m, frame)
            raise RegistrationError(f"no point of the sweep lies within {within}: there is nothing to register", source="kiss")
        return np.array(kiss.last_pose, dtype=np.float64)

    def _register(self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray):
        from kiss_icp.mapping import get_voxel_hash_map
        from kiss_icp.preprocess import Preprocessor
        from kiss_icp.registration import get_registration
        from kiss_icp.voxelization import voxel_down_sample

        c = self.config
        kcfg = self.kiss_config
        crop = Preprocessor(c.max_range_m, c.min_range_m, False, c.max_num_threads)
        no_times, identity = np.array([]), np.eye(4)
        target = crop.preprocess(np.ascontiguousarray(target_xyz), no_times, identity)
        source = crop.preprocess(np.ascontiguousarray(source_xyz), no_times, identity)
        for name, cloud, given in (("source cloud", source, source_xyz), ("target cloud", target, target_xyz)):
            if len(cloud) < 3:
                within = local_origin.range_crop_text(c.min_range_m, c.max_range_m, given)
                raise RegistrationError(f"only {len(cloud)} points within {within}", source=name)
        voxel = c.resolved_voxel_size_m
        local_map = get_voxel_hash_map(kcfg)
        local_map.update(voxel_down_sample(target, voxel * 0.5), identity)
        source_down = voxel_down_sample(voxel_down_sample(source, voxel * 0.5), voxel * 1.5)
        sigma = c.fixed_threshold_m if c.fixed_threshold_m is not None else c.initial_threshold_m
        # (building the assessment's map index in a helper thread while kiss-icp registers was measured: no gain, kiss-icp
        # holds the GIL for about half of its align call; benchmarks/results/icp/gil_probe.md)
        T = get_registration(kcfg).align_points_to_map(
            points=source_down,
            voxel_map=local_map,
            initial_guess=kiss_safe_pose(init_T, "init_T"),
            max_correspondance_distance=3.0 * sigma,
            kernel=sigma,
        )
        T = np.array(T, dtype=np.float64)
        # at a cap below kiss-icp's own it likely stopped there (max_num_iterations=1: 0.36 m off on the bundled pair,
        # "converged"); at its default the check would cost every pair a nearest-neighbour pass for a rare case
        step = None
        if c.max_num_iterations < KissConfig.model_fields["max_num_iterations"].default:
            step = still_moving(kcfg.registration, source_down, local_map, T, 3.0 * sigma, sigma)
        reason = "" if step is None else (f"kiss-icp stopped at max_num_iterations={c.max_num_iterations}: one more iteration "
                                          f"moves the pose by a step of norm {step:.2g} (convergence_criterion="
                                          f"{c.convergence_criterion:g})")

        def assess() -> RegistrationResult:
            assessment = assess_alignment(source_down, local_map.point_cloud(), T, 3.0 * sigma)
            return assessment.to_result(
                T, converged=step is None, reason=reason,
                extra={"iterations_reported": False, "threshold_sigma_m": sigma, "source_keypoints": len(source_down)},
            )

        if reason:  # kept with assess=False too (its generic "kiss reports no convergence" did not name the cap)
            assess.backend_reported = {"reason": reason}
        return T, step is None, assess
