"""``ground_filtered``: remove ground points from both clouds, then run ``vanilla``.

On roads a full-cloud point-to-point ICP matches ground rings to ground rings, which pulls the
estimate towards zero forward motion; dropping the ground (the report's fix) removes that bias.
The ground comes from a segmenter of :mod:`lidarkit.registration.ground` (default ``local_plane``, which
follows slopes; ``height`` is the report's fixed level below the sensor).

In open country little may be left once the ground is gone. A frame whose kept points are fewer than
``min_points_kept`` or whose final alignment is degenerate is *flagged* (its reason starts with
:data:`TOO_LITTLE_REASON`) and falls back: ``constant_velocity`` reports it not converged, so the
odometry runner keeps the previous motion and counts it; ``with_ground`` solves again on the full clouds.

A spinning sensor measures while it moves: at 10 m/s a sweep spans 1 m, and the sparse objects left in open
country are warped by it. When the odometry runner hands over per-point times (the simulator, rosbags; not
KITTI odometry, whose scans are already compensated), both clouds are deskewed to their sweep end with the
constant-velocity motion (``init_T``), and the source once more with the estimate (``deskew``).

A 2D scan (a planar laser, e.g. a CARMEN log: every point at one z) holds no ground: the scan plane lies above
the floor. Such a pair is passed through unsegmented to the ``vanilla`` solve (``planar`` as configured), with
``extra["ground_removal"]`` saying so and one log message per instance, so that a variant list run over 3D and
2D data gives ``ground_filtered`` = ``vanilla`` on the 2D logs instead of an error or a scan-plane "ground".

Removing the ground also removes what fixes height, roll and pitch: the poles, trunks and walls that remain
are vertical and let the estimate tilt (on hills, 0.1 m and 0.3 deg per frame, measured). With
``ground_refine`` the result's z, roll and pitch are refined by point-to-plane residuals of the ground points
(which cannot drag the motion along the road, unlike the point-to-point pairs of the report's ICP).

The covariance calibration of ``ground_filtered`` was learned on refined poses assessed without their ground (tiny
z, roll and pitch factors: the refinement fixes what the closed form leaves loose). A pose solved with ground points
in it (the ``with_ground`` and ``thinned_ground`` fallbacks, a 2D pair) is ``vanilla``'s point-to-point ICP and takes
``vanilla``'s entry; one solved without them but left unrefined (the solve did not converge, or too little ground
lay within range) gets the closed form.
``extra["ground_refined"]`` and ``extra["covariance_calibration"]`` say which.
"""

from __future__ import annotations

import contextvars
import dataclasses
import logging
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from lidarkit.geometry import make_se3, se3_fraction, se3_log, so3_exp
from lidarkit.params import changed_fields
from lidarkit.registration import local_origin
from lidarkit.registration.base import Degeneracy, RegistrationResult, check_point_times, check_sweeps_apart
from lidarkit.registration.components.motion import exp_scaled_twist_apply
from lidarkit.registration.ground import (
    DEFAULT_GROUND_SEGMENTER,
    KITTI_SENSOR_HEIGHT_M,
    GroundSegmenter,
    available_ground_segmenters,
    get_ground_segmenter,
)
from lidarkit.registration.planar import is_2d_scan
from lidarkit.registration.registry import register_icp
from lidarkit.registration.vanilla import VanillaConfig, VanillaICP, prepare, staged_icp, target_index

log = logging.getLogger(__name__)

#: ``extra["ground_removal"]`` of a 2D pair, solved without segmentation.
SKIPPED_2D_NOTE = "skipped: 2D scan (all points at one z), no ground to remove"

#: Start of the reason of every frame flagged for having too little left after ground removal.
TOO_LITTLE_REASON = "too little left after ground removal"

#: The fallbacks that solve with ground points in the clouds (all of them, or a thinned share).
FALLBACKS_WITH_GROUND = ("with_ground", "thinned_ground")

#: ``extra["covariance_calibration"]`` of a pose solved with ground points in, by :func:`pose_basis`.
SOLVED_AS_VANILLA = {
    "2D pair": "vanilla's (a 2D pair, solved unsegmented as vanilla)",
    "with_ground": "vanilla's (with_ground fallback: solved as vanilla on the full clouds)",
    "thinned_ground": "vanilla's (thinned_ground fallback: solved as vanilla with a share of the ground points in)",
}

#: What the pose of the result being finished was solved as (:func:`pose_basis`), for :meth:`GroundFilteredICP._calibration`.
_POSE_BASIS: contextvars.ContextVar[str | None] = contextvars.ContextVar("ground_filtered_pose_basis", default=None)

#: The per-point times of the alignment under way, ``(source fractions, target fractions, sweeps_apart)`` (None: no
#: deskew), handed from :meth:`GroundFilteredICP.align` to its ``_align`` through the base class's checks: per call and
#: per thread (kept on the instance, two threads aligning on one instance read each other's and failed or drifted).
_SWEEP_TIMES: contextvars.ContextVar[tuple[np.ndarray, np.ndarray, float] | None] = contextvars.ContextVar(
    "ground_filtered_sweep_times", default=None)


#: The legacy fields each ground method reads (field -> its parameter name in ground_params).
LEGACY_FIELDS_READ = {
    "height": {"sensor_height_m": "sensor_height_m", "ground_threshold_m": "ground_threshold_m"},
    "patchworkpp": {"sensor_height_m": "sensor_height_m"},
    "ransac": {"sensor_height_m": "sensor_height_m", "ransac_distance_m": "distance_threshold_m",
               "ransac_iterations": "num_iterations", "seed": "seed"},
}


class GroundFilteredConfig(VanillaConfig):
    max_correspondence_distance_m: float | None = Field(
        1.5, gt=0, description="ignore pairs farther apart than this (m): what is left after ground removal can be sparse, and "
        "unmatched far points would pull an all-pairs ICP (KITTI 10 scans: 2.2 m end error without, 0.08 m with 1.5 m)"
    )
    ground_method: str = Field(
        DEFAULT_GROUND_SEGMENTER, description="ground segmenter (lidarkit.registration.ground): local_plane, height, ransac, patchworkpp, csf"
    )
    ground_params: dict[str, Any] = Field(default_factory=dict, description="parameters of the ground segmenter")
    sensor_height_m: float = Field(KITTI_SENSOR_HEIGHT_M, ge=0, description="height / ransac / patchworkpp methods: sensor height above the road (m)")
    ground_threshold_m: float = Field(
        0.73, description="height method: points lower than this above the road are ground (1.73-0.73 = 1 m below the sensor)"
    )
    ransac_distance_m: float = Field(0.2, gt=0, description="ransac method: max point-plane distance of ground points (m)")
    ransac_iterations: int = Field(200, ge=1, description="ransac method: RANSAC iterations")
    seed: int = Field(0, description="ransac method: seed of the numpy RANSAC draws")
    min_points_kept: int = Field(
        100, ge=3, description="fewer points left in either cloud after ground removal -> the frame is flagged and falls back"
    )
    fallback_on_degenerate: bool = Field(True, description="a degenerate alignment of the remaining points also flags the frame")
    deskew: bool = Field(
        True, description="with per-point times: deskew both clouds to their sweep end with the constant-velocity motion, then the source with the estimate"
    )
    ground_refine: bool = Field(True, description="refine z, roll and pitch of the result on the ground points (point to plane)")
    fallback_ground_share: float = Field(
        0.1, gt=0, le=1, description="fallback 'thinned_ground': share of the ground points added back (evenly spaced in scan order)"
    )
    fallback_ground_range_m: float | None = Field(None, gt=0, description="fallback 'thinned_ground': only ground within this range (m); None: all")
    fallback: Literal["constant_velocity", "with_ground", "thinned_ground"] = Field(
        "constant_velocity",
        description="flagged frame: 'constant_velocity' (not converged: the runner keeps the previous motion), 'with_ground' (solve on the full "
        "clouds) or 'thinned_ground' (solve again with a share of the ground points added back; constant velocity if that does not converge)",
    )

    @model_validator(mode="after")
    def _check_segmenter(self) -> GroundFilteredConfig:
        if self.ground_method not in available_ground_segmenters():
            raise ValueError(f"unknown ground_method {self.ground_method!r}; available: {', '.join(available_ground_segmenters())}")
        # a legacy field the method does not read, or one that ground_params overrides, changed nothing without a word
        # (sensor_height_m=5 gave the default's pose under local_plane; with ground_params' own it kept 1.73)
        reads = LEGACY_FIELDS_READ.get(self.ground_method, {})
        given = changed_fields(self, {f for fields in LEGACY_FIELDS_READ.values() for f in fields})
        unread = [f for f in given if f not in reads]
        if unread:
            users = sorted({m for m, fields in LEGACY_FIELDS_READ.items() if set(unread) & set(fields)})
            raise ValueError(f"{', '.join(unread)} set(s) the {' / '.join(users)} ground method, not {self.ground_method!r} "
                             f"(its settings go in ground_params)")
        thinning = changed_fields(self, ("fallback_ground_share", "fallback_ground_range_m"))
        if thinning and self.fallback != "thinned_ground":  # (accepted and ignored)
            raise ValueError(f"{', '.join(thinning)} set(s) the 'thinned_ground' fallback, not {self.fallback!r}")
        both = [f for f in given if reads.get(f) in self.ground_params]
        if both:
            raise ValueError(f"{', '.join(both)} given both as a field and in ground_params "
                             f"({', '.join(reads[f] for f in both)}): give it once")
        return self


def ground_segmenter(config: GroundFilteredConfig) -> GroundSegmenter:
    """The configured segmenter; the legacy fields fill in the ``height`` / ``ransac`` parameters not given."""
    params = dict(config.ground_params)
    for field, name in LEGACY_FIELDS_READ.get(config.ground_method, {}).items():  # (patchworkpp kept its 1.73 m without)
        params.setdefault(name, getattr(config, field))
    return get_ground_segmenter(config.ground_method, **params)


def sweep_fraction(point_times_s: np.ndarray) -> np.ndarray | None:
    """``(N,)`` normalised time in the sweep (0 at its first point, 1 at its last); None without a time span."""
    t = np.asarray(point_times_s, dtype=np.float64)
    span = float(t.max() - t.min()) if len(t) else 0.0
    return (t - t.min()) / span if span > 0 and np.isfinite(span) else None


def deskew_to_sweep_end(points_xyz: np.ndarray, fraction: np.ndarray, T_motion: np.ndarray) -> np.ndarray:
    """Points measured at sweep fraction ``s`` moved into the sensor frame of the sweep end, for a sensor whose
    motion over one sweep is ``T_motion`` (constant velocity): ``p_end = exp((s - 1) log T_motion) p`` (the
    ``pipeline`` variant's deskew, :func:`~lidarkit.registration.components.motion.exp_scaled_twist_apply`)."""
    tau = np.asarray(fraction, dtype=np.float64) - 1.0
    return exp_scaled_twist_apply(se3_log(T_motion), tau, np.asarray(points_xyz, dtype=np.float64))


def refine_on_ground(source_ground_xyz: np.ndarray, target_ground_xyz: np.ndarray, T_target_source: np.ndarray, **settings: Any) -> np.ndarray:
    """``T_target_source`` with its z, roll and pitch (target frame) refined on the ground points (:func:`ground_refinement`)."""
    return ground_refinement(source_ground_xyz, target_ground_xyz, T_target_source, **settings)[0]


def ground_refinement(
    source_ground_xyz: np.ndarray, target_ground_xyz: np.ndarray, T_target_source: np.ndarray, iterations: int = 5,
    voxel_m: float = 0.5, max_distance_m: float = 1.0, k: int = 12, max_range_m: float = 30.0, min_normal_z: float = 0.8,
    max_source_points: int = 5000,
) -> tuple[np.ndarray, int]:
    """``(T_target_source with its z, roll and pitch (target frame) refined by point-to-plane ICP of the ground points,
    the Gauss-Newton steps taken)``: 0 steps where too little ground lay within range (the pose is not refined).

    Target normals from the PCA of ``k`` neighbours in the target ground voxelized at ``voxel_m``, within ``max_range_m``
    (beyond, the rings are too far apart for a normal) and at most ``acos(min_normal_z)`` from vertical; each
    Gauss-Newton step solves the 3 x 3 system in (tz, rx, ry) of the residuals ``n . (T p - q)`` within ``max_distance_m``,
    Cauchy-weighted on their median absolute deviation.
    x, y and yaw, which the ground cannot fix without biasing them, are left to the non-ground alignment.
    """
    from scipy.spatial import cKDTree

    from lidarkit.registration.preprocess import voxel_downsample

    def near(points: np.ndarray) -> np.ndarray:
        return points[np.hypot(points[:, 0], points[:, 1]) <= max_range_m]

    target = voxel_downsample(near(target_ground_xyz), voxel_m)
    source = near(source_ground_xyz)  # raw points lie on the ground; voxel centroids of a moved copy need not
    if len(source) > max_source_points:
        source = source[np.random.default_rng(0).choice(len(source), max_source_points, replace=False)]
    if len(target) < k or len(source) < 10:
        return T_target_source, 0
    _, nbr = cKDTree(target).query(target, k=k)
    centred = target[nbr] - target[nbr].mean(axis=1, keepdims=True)
    evals, evecs = np.linalg.eigh(np.einsum("nki,nkj->nij", centred, centred))
    normals = evecs[:, :, 0]
    planar = (np.abs(normals[:, 2]) >= min_normal_z) & (evals[:, 0] < 0.1 * evals[:, 1])
    target, normals = target[planar], normals[planar]
    if len(target) < k:
        return T_target_source, 0
    tree = cKDTree(target)
    T = np.array(T_target_source, dtype=np.float64)
    steps = 0
    for _ in range(iterations):
        p = np.einsum("ij,nj->ni", T[:3, :3], source) + T[:3, 3]
        dist, idx = tree.query(p, distance_upper_bound=max_distance_m)
        ok = np.isfinite(dist)
        if ok.sum() < 10:
            break
        n, q, pp = normals[idx[ok]], target[idx[ok]], p[ok]
        r = np.einsum("ni,ni->n", n, pp - q)
        # Cauchy weights on the MAD scale: the feet of walls that segmentation left in the ground do not pull
        scale = max(1.4826 * float(np.median(np.abs(r))), 1e-3)
        w = 1.0 / (1.0 + (r / (3.0 * scale)) ** 2)
        pxn = np.cross(pp, n)
        J = np.stack([n[:, 2], pxn[:, 0], pxn[:, 1]], axis=1)
        H = J.T @ (w[:, None] * J)
        if np.linalg.cond(H) > 1e8:
            break
        tz, rx, ry = np.linalg.solve(H, -J.T @ (w * r))
        T = make_se3(so3_exp(np.array([rx, ry, 0.0])), np.array([0.0, 0.0, tz])) @ T
        steps += 1
        if abs(tz) < 1e-5 and abs(rx) < 1e-6 and abs(ry) < 1e-6:
            break
    return T, steps


def thin_ground(points_xyz: np.ndarray, ground: np.ndarray, share: float, max_range_m: float | None = None) -> np.ndarray:
    """``(N,)`` mask of an evenly spaced ``share`` of the ``ground`` points (at a stride of ``1 / share`` in scan order,
    fractional, so every ring and direction keeps some: a whole stride made 0.7 every point and 0.4 every other one),
    within ``max_range_m`` horizontally if given."""
    pick = ground.copy()
    if max_range_m is not None:
        pick &= np.hypot(points_xyz[:, 0], points_xyz[:, 1]) <= max_range_m
    idx = np.flatnonzero(pick)
    out = np.zeros(len(ground), dtype=bool)
    out[idx[np.floor(np.arange(0.0, len(idx), 1.0 / share)).astype(np.int64)]] = True
    return out


def _degenerate_after_refine(degeneracy: Degeneracy, ground_refine: bool) -> bool:
    """Degenerate in a direction nothing fixes: with ``ground_refine`` the ground fixes z, roll and pitch, so a weakly
    constrained problem counts when its weakest direction lies mostly in x, y and yaw, or when it is singular
    (min/max eigenvalue < 1e-4: a null space of several directions, e.g. a single wall, whose weakest vector is
    an arbitrary member)."""
    if not degeneracy.degenerate:
        return False
    if not ground_refine or degeneracy.ratio < 1e-4:
        return True
    w = np.asarray(degeneracy.weakest_direction, dtype=np.float64)
    return bool(w[0] ** 2 + w[1] ** 2 + w[5] ** 2 > 0.5)


def pose_basis(extra: dict[str, Any], planar: bool) -> str | None:
    """How a result's pose was solved, from its ``extra``, where that is not what ground_filtered's calibration entry was
    learned on: ``"2D pair"`` / ``"with_ground"`` / ``"thinned_ground"`` (solved with ground points in: vanilla's ICP),
    ``"unrefined"`` (without the ground, but not refined on it; ``planar`` keeps z, roll and pitch of the guess and
    their covariance is zeroed, so its x, y and yaw stay with the entry), None (as learned)."""
    if extra.get("ground_removal") == SKIPPED_2D_NOTE:
        return "2D pair"
    if extra.get("ground_removal_flagged") and extra.get("fallback") in FALLBACKS_WITH_GROUND:
        return str(extra["fallback"])
    return "unrefined" if not extra.get("ground_refined") and not planar else None


def ground_mask(points_xyz: np.ndarray, config: GroundFilteredConfig) -> np.ndarray:
    """``(N,)`` bool mask of ground points according to the config."""
    return ground_segmenter(config).segment(points_xyz)


@register_icp("ground_filtered")
class GroundFilteredICP(VanillaICP):
    """Ground removal (a registry segmenter, default slope-following local planes) followed by point-to-point ICP."""

    Config = GroundFilteredConfig
    #: the odometry runner passes ``source_times_s`` / ``target_times_s`` (per-point times) to :meth:`align`
    accepts_point_times = True
    #: ... and ``sweeps_apart`` (a pair that skips sweeps: the deskew motion is scaled to one sweep)
    accepts_sweeps_apart = True

    def __init__(self, config: GroundFilteredConfig | None = None, **params: Any):
        super().__init__(config, **params)
        self.segmenter = ground_segmenter(self.config)
        self._told_2d = False

    @property
    def deskew_instant(self) -> str | None:
        """The instant of the sweep deskewed poses refer to: both clouds are moved to their sweep END."""
        return "end" if self.config.deskew else None

    def align(
        self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray | None = None, *,
        source_times_s: np.ndarray | None = None, target_times_s: np.ndarray | None = None, sweeps_apart: float = 1.0,
    ) -> RegistrationResult:
        """As :meth:`Registration.align`; with both clouds' per-point times (s) and ``deskew`` the clouds are deskewed.
        ``sweeps_apart``: sweeps between target and source; their motion, taken as one sweep's, deskewed a pair 3
        sweeps apart (``--frames 0:60:3``) three times too much (worse than no deskew): it is scaled to one sweep."""
        fractions: list[np.ndarray | None] = [None, None]
        if self.config.deskew and source_times_s is not None and target_times_s is not None:
            for k, (name, pts, times) in enumerate((("source", source_xyz, source_times_s), ("target", target_xyz, target_times_s))):
                fractions[k] = sweep_fraction(check_point_times(times, len(pts), f"{name} times"))
        sweeps_apart = check_sweeps_apart(sweeps_apart)
        timed = fractions[0] is not None and fractions[1] is not None
        token = _SWEEP_TIMES.set((fractions[0], fractions[1], sweeps_apart) if timed else None)
        try:
            return super().align(source_xyz, target_xyz, init_T)
        finally:
            _SWEEP_TIMES.reset(token)

    def _align(self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray) -> RegistrationResult:
        c = self.config
        if is_2d_scan(source_xyz) or is_2d_scan(target_xyz):
            if not self._told_2d:
                log.info("ground_filtered: 2D scans hold no ground; solving them unsegmented (vanilla%s)", ", planar" if c.planar else "")
                self._told_2d = True
            result = super()._align(source_xyz, target_xyz, init_T)
            return dataclasses.replace(result, extra={**result.extra, "ground_removal": SKIPPED_2D_NOTE, "ground_method": c.ground_method,
                                                      "ground_refined": False})
        ground = [self.segmenter.segment(pts) for pts in (source_xyz, target_xyz)]
        sweep_times = _SWEEP_TIMES.get()
        masks = [~g for g in ground]
        kept = {"source_points_kept": int(masks[0].sum()), "target_points_kept": int(masks[1].sum()), "ground_method": c.ground_method}
        fewest = min(kept["source_points_kept"], kept["target_points_kept"])
        if fewest < c.min_points_kept:
            why = f"{TOO_LITTLE_REASON}: {fewest} points (min_points_kept={c.min_points_kept}, {c.ground_method})"
            return self._fallback(source_xyz, target_xyz, init_T, why, kept, ground, sweep_times)
        result = self._solve(source_xyz, target_xyz, init_T, masks, ground, sweep_times)
        if c.fallback_on_degenerate and result.converged and _degenerate_after_refine(result.degeneracy, c.ground_refine and not c.planar):
            why = f"{TOO_LITTLE_REASON}: degenerate geometry (min/max eigenvalue {result.degeneracy.ratio:.1e}, {c.ground_method})"
            return self._fallback(source_xyz, target_xyz, init_T, why, kept, ground, sweep_times, result.degeneracy)
        return dataclasses.replace(result, extra={**result.extra, **kept})

    def _finish(self, result: RegistrationResult, runtime: float) -> RegistrationResult:
        """As :meth:`Registration._finish`, with the calibration of what this pose was solved as (:func:`pose_basis`):
        ground_filtered's entry, learned on refined poses assessed without the ground, has z, roll and pitch factors of
        5e-6 to 4e-5; on a with_ground pose (vanilla's ICP on the full clouds) it gave NEES 629 where vanilla's gives 6.4
        (KITTI 94/95, road only)."""
        basis = pose_basis(result.extra, self.config.planar)
        token = _POSE_BASIS.set(basis)
        try:
            finished = super()._finish(result, runtime)
        finally:
            _POSE_BASIS.reset(token)
        if basis in SOLVED_AS_VANILLA and "covariance_calibration" in finished.extra:
            finished = dataclasses.replace(finished, extra={**finished.extra, "covariance_calibration": SOLVED_AS_VANILLA[basis]})
        return finished

    def _calibration(self) -> tuple[str | None, list[str]]:
        """The entry of :meth:`Registration._calibration`, for the pose being finished: vanilla's where it was solved
        with ground points in, none (the closed form) where it was solved without them but not refined."""
        learned, unlearned = super()._calibration()
        basis = _POSE_BASIS.get()
        if basis in SOLVED_AS_VANILLA:
            return "vanilla", []
        if basis == "unrefined" and learned is not None and not unlearned:
            return learned, ["pose not ground-refined"]
        return learned, unlearned

    def _solve(
        self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray, masks: list[np.ndarray],
        ground: list[np.ndarray], sweep_times: tuple[np.ndarray, np.ndarray, float] | None,
    ) -> RegistrationResult:
        """Staged ICP of the points ``masks`` keep (deskewed when ``sweep_times``, the clouds' sweep fractions and
        ``sweeps_apart``, came), then the ground refinement on the ``ground`` points."""
        c = self.config
        clouds = [pts[m] for pts, m in zip((source_xyz, target_xyz), masks)]
        deskew = sweep_times is not None
        if deskew:
            frac_src, frac_dst, sweeps_apart = sweep_times[0][masks[0]], sweep_times[1][masks[1]], sweep_times[2]
            raw_source = clouds[0]
            sweep = se3_fraction(init_T, sweeps_apart)
            clouds = [deskew_to_sweep_end(clouds[0], frac_src, sweep), deskew_to_sweep_end(clouds[1], frac_dst, sweep)]
        src, dst = prepare(clouds[0], clouds[1], c.voxel_size_m)
        neighbors = target_index(src, dst, c, self.name)
        result = staged_icp(src, dst, init_T, neighbors, c)
        if deskew and result.converged:  # once more with the source deskewed by the estimated motion
            src = prepare(deskew_to_sweep_end(raw_source, frac_src, se3_fraction(result.T_target_source, sweeps_apart)), clouds[1], c.voxel_size_m)[0]
            first = result
            result = staged_icp(src, dst, result.T_target_source, neighbors, c)
            result = dataclasses.replace(result, iterations=first.iterations + result.iterations, extra={**result.extra, "deskewed": True})
        if c.ground_refine and result.converged and not c.planar:  # planar: z, roll and pitch stay as in init_T
            # raw ground points: the sweep's motion mostly slides them along the ground, which a plane residual ignores,
            # and deskewing them with a motion that carries the last frame's tilt error would feed that error back
            grounds = [pts[g] for pts, g in zip((source_xyz, target_xyz), ground)]
            # clouds far from their frame's origin (georeferenced, a map frame) are refined around the target's likely
            # sensor: the ground's range and the tilt's lever arms are the sensor's (about the far origin nothing lay
            # within range and the pose came back unrefined)
            centre = local_origin.sensor_proxy(target_xyz)
            refined, steps = ground_refinement(local_origin.shift(grounds[0], centre), local_origin.shift(grounds[1], centre),
                                               local_origin.into(result.T_target_source, centre, centre))
            if steps:  # (none: too little ground within range, the pose stays as solved)
                refined = local_origin.out_of(refined, centre, centre)
                # the covariance and surface_step stay those of the alignment before it: the calibration was learned so
                return dataclasses.replace(result, T_target_source=refined, extra={**result.extra, "ground_refined": True})
        return dataclasses.replace(result, extra={**result.extra, "ground_refined": False})  # (its calibration: pose_basis)

    def _fallback(
        self, source_xyz: np.ndarray, target_xyz: np.ndarray, init_T: np.ndarray, why: str, kept: dict, ground: list[np.ndarray],
        sweep_times: tuple[np.ndarray, np.ndarray, float] | None, degeneracy: Degeneracy | None = None,
    ) -> RegistrationResult:
        c = self.config
        extra = {**kept, "ground_removal_flagged": True, "fallback": c.fallback}
        if c.fallback == "thinned_ground":
            masks = [~g | thin_ground(local_origin.shift(pts, local_origin.sensor_proxy(pts)), g, c.fallback_ground_share, c.fallback_ground_range_m)
                     for pts, g in zip((source_xyz, target_xyz), ground)]  # (ranges from the likely sensor, see _solve)
            result = self._solve(source_xyz, target_xyz, init_T, masks, ground, sweep_times)
            if result.converged:  # (its own reason kept, as with_ground's: "degenerate geometry: ..." was dropped)
                reason = f"{why}; solved with {c.fallback_ground_share:g} of the ground points added back" + (
                    f"; {result.reason}" if result.reason else "")
                return dataclasses.replace(result, reason=reason, extra={**result.extra, **extra})
        if c.fallback == "with_ground":
            src, dst = prepare(source_xyz, target_xyz, c.voxel_size_m)
            neighbors = target_index(src, dst, c, self.name)
            result = staged_icp(src, dst, init_T, neighbors, c)
            reason = f"{why}; solved with the ground included" + (f"; {result.reason}" if result.reason else "")
            return dataclasses.replace(result, reason=reason, extra={**result.extra, **extra, "ground_refined": False})
        return RegistrationResult(
            T_target_source=init_T.copy(),
            converged=False,
            iterations=0,
            rmse_history=(),
            n_correspondences=0,
            runtime_s=0.0,
            fitness=0.0,
            degeneracy=degeneracy if degeneracy is not None else Degeneracy.unknown("too few points after ground removal"),
            reason=why,  # (the motion that replaces the pose is the odometry runner's to say, not a pairwise alignment's)
            extra={**extra, "ground_refined": False},
        )
