"""The monocular VO pipeline: preprocessing -> features -> correspondences -> two-view pose -> sanity -> scale -> chain.

``MonoVO(config, K, ground_truth).run(images)`` returns a :class:`VOResult`: the raw trajectory (one pose per
input frame, camera frame, start pose = identity or its ground-truth pose), per-frame diagnostics with
the reason for every rejected frame, and the smoothed trajectory on demand. A rejected frame never yields a NaN
pose: a frame without parallax w.r.t. the reference (standstill, pure rotation) stays at the reference position
(with the estimated rotation when there is one); any other rejected frame gets a constant-velocity (or identity)
motion, and one before the first accepted pair the motion of that pair. The next frame is matched against the last
accepted one. The image size of the sequence is the majority size of its first readable frames, so an odd-sized
first frame is rejected like any other odd frame.
"""

from __future__ import annotations

import logging
import os
import re
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, NamedTuple

import cv2
import numpy as np

from lidarkit.errors import ConfigError, DataError, index_runs
from lidarkit.geometry import is_rotation, rotation_angle_deg, se3_fraction, se3_inverse, skew
from lidarkit.trajectory import Trajectory
from lidarkit.vo.config import FeatureConfig, GeometryConfig, VOConfig
from lidarkit.vo.features import get_detector, get_preprocessor
from lidarkit.vo.intrinsics import validate_K
from lidarkit.vo.matching import get_matcher, track_klt
from lidarkit.vo.sanity import check_pose
from lidarkit.vo.scale import SCALE_KEPT_NOTE, guarded_scale, relative_scale
from lidarkit.vo.smoothing import smooth_translations
from lidarkit.vo.two_view import (correspondence_rng, estimate_two_view, normalize_points, rotation_only_fit,
                                  sampson_residuals, triangulate)

log = logging.getLogger(__name__)

# rejection reasons after which the reference frame moves on (a farther frame would match it even worse)
_TRACKING_LOST = ("too few matches", "too few inliers", "too few pose inliers", "no essential")
# rejection reason (lidarkit.vo.sanity.check_pose) of a pair without parallax: standstill or pure rotation
_NO_PARALLAX = "insufficient parallax"
# two-view geometry of the scale corners' own pose (scale.corner_pose == "corners"): lidarkit's default (E-RANSAC
# 0.5 px on normalized points + Sampson refinement), whatever the pipeline's geometry is
_CORNER_GEOMETRY = GeometryConfig()
#: Smallest image side (px) a sequence's frames may have: ORB's and AKAZE's pyramids fail below a patch's size.
MIN_IMAGE_SIDE_PX = 32

# the sequence's image size is the majority size of the first _SIZE_VOTES readable frames among the first _SIZE_PROBE
_SIZE_VOTES, _SIZE_PROBE = 5, 10


class TrackingFailedError(DataError):
    """No frame pair of a sequence could be estimated: the trajectory holds no measurement."""


def rejection_key(reason: str) -> str:
    """The kind of a rejection reason without its numbers and details, e.g. ``"too few matches"`` for
    ``"too few matches (3 < 30)"`` or ``"image size"`` for ``"image size 640x200 differs from ..."``."""
    return re.split(r" \(|:|\d", reason, maxsplit=1)[0].strip() or reason


@dataclass
class FrameDiagnostics:
    """What happened at one frame (frame 0 is the start and always accepted)."""

    frame: int
    ref_frame: int
    n_features: int = 0
    n_matches: int = 0
    n_inliers: int = 0
    method: str = ""
    rotation_deg: float = float("nan")
    parallax_px: float = float("nan")
    scale: float = float("nan")
    n_scale_points: int = 0
    accepted: bool = False
    reason: str = ""
    note: str = ""
    runtime_ms: float = 0.0


@dataclass
class Features:
    """Features of one frame: ``points_px (M, 2) float32``, ``descriptors (M, D)`` or None, ``depth (M,)`` in the
    trajectory's scale (NaN where unknown)."""

    points_px: np.ndarray
    descriptors: np.ndarray | None
    depth: np.ndarray
    # relative scale with ``scale.points == "corners"``: the corners carrying depth, ``(K, 2)`` px, ``(K,)`` depth
    # and ``(K,)`` number of pair views averaged into it
    scale_points_px: np.ndarray | None = None
    scale_points_depth: np.ndarray | None = None
    scale_points_views: np.ndarray | None = None

    @classmethod
    def fresh(cls, points_px: np.ndarray, descriptors: np.ndarray | None) -> Features:
        return cls(points_px, descriptors, np.full(len(points_px), np.nan))


class TrackedScalePoints(NamedTuple):
    """Scale points of one pair: reference depth ``(K,)`` (NaN for fresh corners) and the views behind it ``(K,)``,
    positions in both frames ``(K, 2)`` px, unit-baseline triangulations in both frames ``(K, 3)``, triangulation
    angles ``(K,)`` deg, usable mask ``(K,)``, and the pose ``R_cur_ref (3, 3)``, unit ``t_cur_ref (3,)`` they
    were triangulated with."""

    depth_ref: np.ndarray
    views_ref: np.ndarray
    points_ref_px: np.ndarray
    points_cur_px: np.ndarray
    X_ref: np.ndarray
    X_cur: np.ndarray
    angle_deg: np.ndarray
    usable: np.ndarray
    R_cur_ref: np.ndarray
    t_cur_ref: np.ndarray


@dataclass
class VOResult:
    """Output of :meth:`MonoVO.run`."""

    trajectory: Trajectory
    diagnostics: list[FrameDiagnostics]
    config: VOConfig
    K: np.ndarray
    runtime_s: float
    tracks: list[tuple[int, np.ndarray, np.ndarray]] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __repr__(self) -> str:
        """One line of counts (the generated one printed every frame's diagnostics: ~550 characters a frame)."""
        name = f"{self.trajectory.name!r}, " if self.trajectory.name else ""
        pairs = max(self.n_frames - 1 - int(self.meta.get("start_frame", 0)), 0)
        return (f"VOResult({name}{self.n_frames} frames in {self.runtime_s:.3g} s, {max(self.accepted_pairs, 0)} of {pairs} pairs "
                f"accepted, scale {self.config.scale.mode})")

    @property
    def n_frames(self) -> int:
        return len(self.trajectory)

    @property
    def rejected(self) -> list[FrameDiagnostics]:
        return [d for d in self.diagnostics if not d.accepted]

    @property
    def frames_per_s(self) -> float:
        """Processed frames per second of pipeline time (image reading excluded)."""
        return self.n_frames / self.runtime_s if self.runtime_s > 0 else float("inf")

    @property
    def n_scale_kept(self) -> int:
        """Frames whose relative scale was kept from the previous step (too few common points, or a change beyond
        ``scale.max_step_change``); 0 for the other scale modes."""
        return sum(1 for d in self.diagnostics if d.note.startswith(SCALE_KEPT_NOTE))

    def smoothed(self) -> Trajectory:
        """Translations smoothed with the configured Savitzky-Golay filter, against the time stamps when the run has
        them (a dropped frame is a longer step; see :func:`smooth_translations`); rotations unchanged. Only from the
        start frame on: the frames before it (unreadable) hold its pose, and smoothed with the rest they pulled the
        first estimates back (APE 0.12 m instead of 0.004 m after one bad first frame of KITTI 06)."""
        s = self.config.smoothing
        first = int(self.meta.get("start_frame", 0))
        if first == 0:
            return smooth_translations(self.trajectory, s.window, s.polyorder)
        tail = smooth_translations(self.trajectory[np.arange(first, len(self.trajectory))], s.window, s.polyorder)
        poses = np.concatenate([np.repeat(tail.poses_se3[:1], first, axis=0), tail.poses_se3])
        return Trajectory(poses, self.trajectory.timestamps_s, name=tail.name, meta=tail.meta)

    def diagnostics_rows(self) -> list[dict[str, Any]]:
        return [asdict(d) for d in self.diagnostics]

    @property
    def accepted_pairs(self) -> int:
        """Frames whose pose was estimated from a frame pair (the start frame is not counted)."""
        return sum(d.accepted for d in self.diagnostics) - 1

    def rejection_counts(self) -> dict[str, int]:
        """``{rejection kind: frames}``, most frequent first (see :func:`rejection_key`)."""
        return dict(Counter(rejection_key(d.reason) for d in self.rejected).most_common())

    def check_tracking(self) -> None:
        """Raise :class:`TrackingFailedError` naming the most common rejection when the sequence has frame pairs but
        none was accepted (the trajectory is then pure prediction)."""
        pairs = self.n_frames - 1
        if pairs >= 1 and self.accepted_pairs == 0:
            kind, count = next(iter(self.rejection_counts().items()))
            example = next(d.reason for d in self.rejected if rejection_key(d.reason) == kind)
            raise TrackingFailedError(f"no frame pair accepted ({len(self.rejected)} of {self.n_frames} frames "
                                      f"rejected); most common reason ({count}x): {example}",
                                      source=self.trajectory.name or "vo")

    def summary(self) -> dict[str, Any]:
        return {
            "frames": self.n_frames,
            "accepted_pairs": self.accepted_pairs,
            "rejected": len(self.rejected),
            "rejection_reasons": self.rejection_counts(),
            "runtime_s": self.runtime_s,
            "frames_per_s": self.frames_per_s,
            "scale_mode": self.config.scale.mode,
            "scale_kept_frames": self.n_scale_kept,
        }


class MonoVO:
    """Frame-to-frame monocular VO configured by a :class:`VOConfig`.

    ``K``: ``(3, 3)`` intrinsics of the (undistorted) images; ``ground_truth``: camera-frame trajectory with one
    pose per frame, required for ``scale.mode == "gt"`` (per-step norms) and used to anchor the first pose.
    """

    def __init__(self, config: VOConfig | None = None, K: np.ndarray | None = None,
                 ground_truth: Trajectory | None = None):
        if config is not None and not isinstance(config, VOConfig):  # (a dict: an AttributeError traceback)
            raise ConfigError(f"config must be a VOConfig (lidarkit.vo.preset(...) or VOConfig(...)), got {type(config).__name__}",
                              source="MonoVO")
        self.config = config or VOConfig()
        if K is None:
            raise ConfigError("intrinsics K are required (use lidarkit.vo.intrinsics.K_from_image_size to guess them)",
                              source="MonoVO")
        self.K = validate_K(K)
        self.ground_truth = ground_truth
        if self.config.scale.mode == "gt" and ground_truth is None:
            raise ConfigError("scale mode 'gt' needs a ground-truth trajectory", source="vo scale.mode")
        self.preprocess = get_preprocessor(self.config.preprocess)
        self.detector = get_detector(self.config.features)
        self.matcher = None if self.config.matching.method == "klt" else get_matcher(self.config.matching,
                                                                                      self.detector.norm)
        own = self.matcher is None and self.config.features.detector == "gftt"
        self._scale_detector = (get_detector(FeatureConfig()) if self.config.scale.mode == "relative"
                                and self.config.scale.points == "corners" and not own else None)
        self._rejected_R_cur_ref: np.ndarray | None = None  # set by _estimate on a rejection

    # ---- public ----------------------------------------------------------------------------------------------
    def run(self, images: Any, keep_tracks: bool = False, timestamps_s: np.ndarray | None = None,
            on_frame: Callable[[int], None] | None = None) -> VOResult:
        """Estimate one camera pose per image.

        ``images``: an ``ImageSequence`` (``len`` + ``read_image(i)``; a DataError from it rejects that frame) or a
        sequence of ``(H, W)`` uint8 arrays (None marks an unreadable frame). ``keep_tracks`` stores the inlier
        correspondences of every accepted frame (for the feature GIF). ``on_frame(index)`` is called as each frame is
        done (a progress bar).
        """
        # a path string was read as one frame per character, a Path failed on len()
        if isinstance(images, (str, bytes, os.PathLike)):
            folder = os.fsdecode(images)
            raise DataError(f"a path is no image sequence: pass lidarkit.io.images.ImageFolder({folder!r})",
                            source="MonoVO.run images")
        if not hasattr(images, "__len__") or not (hasattr(images, "read_image") or hasattr(images, "__getitem__")):
            raise DataError(f"a {type(images).__name__} is neither an ImageSequence (len + read_image) nor a list of "
                            "(H, W) uint8 arrays", source="MonoVO.run images")
        n = len(images)
        if n < 1:
            raise DataError("no images to process", source=getattr(images, "name", "images"))
        if self.ground_truth is not None and len(self.ground_truth) != n:
            raise DataError(f"ground truth has {len(self.ground_truth)} poses for {n} images",
                            source="vo ground_truth")
        if timestamps_s is None:
            timestamps_s = getattr(images, "timestamps_s", None)
        if timestamps_s is not None:  # checked before the frames (a wrong length failed after all of them)
            try:
                stamps = np.asarray(timestamps_s, dtype=np.float64).reshape(-1)
            except (TypeError, ValueError) as err:  # (a list of text was numpy's own ValueError)
                raise DataError(f"time stamps must be numbers in seconds ({err})", source="vo timestamps_s") from None
            if len(stamps) != n or not np.isfinite(stamps).all() or not (np.diff(stamps) > 0).all():
                raise DataError(f"{len(stamps)} time stamps for {n} images, which must be finite and increasing",
                                source="vo timestamps_s")
        read = images.read_image if hasattr(images, "read_image") else (lambda i: images[i])

        cfg = self.config
        poses = np.zeros((n, 4, 4))
        poses[0] = self.ground_truth.poses_se3[0] if self.ground_truth is not None else np.eye(4)
        diags: list[FrameDiagnostics] = []
        tracks: list[tuple[int, np.ndarray, np.ndarray]] | None = [] if keep_tracks else None
        step_motion = np.eye(4)  # T_prev_cur of the last accepted step, per frame (for constant velocity)
        last_scale = 1.0
        total_s = 0.0

        loaded: dict[int, tuple[np.ndarray | None, str]] = {}
        image_shape = sequence_image_shape(images, loaded)
        note = intrinsics_mismatch(self.K, image_shape)
        if note:
            log.warning("%s: %s", getattr(images, "name", "images"), note)

        def load(index: int) -> tuple[np.ndarray | None, str]:
            image, reason = loaded.pop(index) if index in loaded else self._load(read, index)
            if image is not None and image.shape != image_shape:
                return None, (f"image size {image.shape[1]}x{image.shape[0]} differs from the sequence's "
                              f"{image_shape[1]}x{image_shape[0]}")
            return image, reason

        # the start is the first frame of the sequence's size; unusable frames before it stay at the start pose
        s, (first, first_reason) = 0, load(0)
        while first is None:
            diags.append(FrameDiagnostics(frame=s, ref_frame=s, reason=first_reason, note="before the start frame"))
            log.info("frame %d rejected: %s", s, first_reason)
            s += 1
            first, first_reason = load(s)
        if self.ground_truth is not None:
            poses[: s + 1] = self.ground_truth.poses_se3[s]
        else:
            poses[: s + 1] = poses[0]
        start = time.perf_counter()
        ref_index, ref_image = s, self.preprocess(first)
        ref_feats = self._reference_features(ref_image, None)
        n_still = 0  # frames since the reference rejected for lack of parallax (the camera stood still)
        previous_lost = False  # the previous frame was rejected because tracking against the reference was lost
        n_accepted = 0  # frame pairs accepted so far
        total_s += time.perf_counter() - start
        diags.append(FrameDiagnostics(frame=s, ref_frame=s, n_features=len(ref_feats.points_px), accepted=True,
                                      note="start"))
        for k in range(s + 1) if on_frame is not None else ():  # the start frame and the unusable ones before it
            on_frame(k)

        for j in range(s + 1, n):
            image, reason = load(j)
            start = time.perf_counter()
            # for OpenCV calls that do use its RNG; a C int (seed 2148 overflowed it: "integer won't fit into a C int")
            cv2.setRNGSeed((int(cfg.seed or 0) * 1_000_003 + j) % 2**31)
            diag = FrameDiagnostics(frame=j, ref_frame=ref_index, n_features=len(ref_feats.points_px))
            result = None
            cur_image = None
            if image is not None:
                cur_image = self.preprocess(image)
                result, reason = self._estimate(ref_index, ref_image, ref_feats, j, cur_image, diag, last_scale,
                                                n_still, first_pair=n_accepted == 0)
            if result is not None:
                T_ref_cur, cur_feats, scale, pts = result
                poses[j] = poses[ref_index] @ T_ref_cur
                moving = j - ref_index - n_still  # frame steps with motion (standstill frames excluded)
                step_motion = _per_frame_motion(T_ref_cur, moving)
                last_scale = scale / moving
                if n_accepted == 0 and n_still == 0:
                    # frames rejected before the first pair had no velocity to predict from and kept the start
                    # pose (1.2 m off after one unreadable frame 1 of KITTI 06: APE x65): place them on its motion
                    for k in range(ref_index + 1, j):
                        poses[k] = poses[k - 1] @ self._predicted_motion(step_motion, k)
                        diags[k].note = diags[k].note or "placed on the first accepted motion"
                diag.accepted = True
                n_accepted += 1
                if tracks is not None:
                    tracks.append((j, *pts))
                ref_index, ref_image, n_still, previous_lost = j, cur_image, 0, False
                ref_feats = self._reference_features(cur_image, cur_feats)
            else:
                diag.reason = reason or "rejected"
                if diag.reason.startswith(_NO_PARALLAX):
                    # no translation w.r.t. the reference: stay there, turned by the estimated rotation if any
                    poses[j] = poses[ref_index] @ self._standstill_motion()
                    n_still += 1
                else:
                    poses[j] = poses[j - 1] @ self._predicted_motion(step_motion, j)
                log.info("frame %d rejected: %s", j, diag.reason)
                # move the reference to this frame when the reference cannot serve (too few features), after a long
                # gap of moving frames (a standstill keeps its reference and depths), or when tracking was lost on two
                # frames in a row (a later frame would be even farther from the reference; one unrelated frame, e.g.
                # corrupt or mis-ordered, must not take over); a frame without features of its own never does
                stale = j - ref_index - n_still >= 5 or len(ref_feats.points_px) < cfg.sanity.min_features
                lost = diag.reason.startswith(_TRACKING_LOST)
                lost_twice, previous_lost = lost and previous_lost, lost
                if cur_image is not None and (stale or lost_twice):
                    candidate = self._reference_features(cur_image, None)
                    if len(candidate.points_px) >= cfg.sanity.min_features:
                        ref_index, ref_image, ref_feats, n_still = j, cur_image, candidate, 0
                        diag.note = "reference moved to this frame"
            elapsed = time.perf_counter() - start
            total_s += elapsed
            diag.runtime_ms = 1000.0 * elapsed
            diags.append(diag)
            if on_frame is not None:
                on_frame(j)

        if not np.all(np.isfinite(poses)):  # defensive: must never happen
            raise DataError("non-finite pose produced", source="MonoVO")
        traj = Trajectory(poses, None if timestamps_s is None else np.asarray(timestamps_s, dtype=float),
                          name=f"vo_{cfg.features.detector}_{cfg.matching.method}_{cfg.scale.mode}")
        return VOResult(traj, diags, cfg, self.K, total_s, tracks,
                        meta={"image_size_wh": [int(image_shape[1]), int(image_shape[0])], "start_frame": s})

    # ---- steps -----------------------------------------------------------------------------------------------
    @staticmethod
    def _load(read, index: int) -> tuple[np.ndarray | None, str]:
        """The image as uint8 (H, W) or (None, reason); a grayscale one may come as (H, W, 1)."""
        try:
            image = read(index)
        except DataError as err:
            return None, f"unreadable image: {err}"
        if isinstance(image, DataError):  # (images_in_memory's unreadable image: its reason, not "missing")
            return None, f"unreadable image: {image}"
        if image is None:
            return None, "unreadable image (missing)"
        image = np.asarray(image)
        if image.ndim == 3 and image.shape[2] == 1:  # (refused as "not a grayscale image")
            image = image[:, :, 0]
        colour = image.ndim == 3 and image.shape[2] in (3, 4)
        if image.size == 0 or not (image.ndim == 2 or colour):
            return None, f"not a grayscale image (shape {image.shape})"
        if image.dtype != np.uint8:  # (before the colour conversion: OpenCV's raised a traceback for float64 BGR)
            return None, f"image dtype {image.dtype} is not uint8 ({_uint8_hint(image.dtype)})"
        if colour:
            image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
        return image, ""

    def _reference_features(self, image: np.ndarray, carried: Features | None) -> Features:
        """Features of the new reference frame: KLT adds fresh corners to the carried tracks; descriptor pipelines
        reuse the detections made when the frame was the current one."""
        if self.matcher is not None:
            if carried is not None:
                return carried
            return Features.fresh(*self.detector.detect(image))
        fresh = Features.fresh(*self.detector.detect(image))
        if carried is None or len(carried.points_px) == 0:
            return fresh
        keep = np.flatnonzero(np.isfinite(carried.depth))[: self.config.scale.max_carried_points]
        return Features(np.concatenate([carried.points_px[keep], fresh.points_px]).astype(np.float32), None,
                        np.concatenate([carried.depth[keep], fresh.depth]), carried.scale_points_px,
                        carried.scale_points_depth, carried.scale_points_views)

    def _estimate(self, ref_index: int, ref_image: np.ndarray, ref: Features, j: int, cur_image: np.ndarray,
                  diag: FrameDiagnostics, last_scale: float, n_still: int = 0, first_pair: bool = True):
        """Relative pose of frame j w.r.t. the reference; ``(T_ref_cur, cur_features, scale, (pts_ref, pts_cur))``
        or ``(None, reason)``. ``n_still``: frames since the reference rejected as standstill (not counted as
        motion by unit steps); ``first_pair``: no pair accepted yet (relative scale starts at 1 without a note). A
        rejected pose's valid rotation is kept in ``self._rejected_R_cur_ref``."""
        cfg = self.config
        self._rejected_R_cur_ref = None
        if len(ref.points_px) < cfg.sanity.min_features:
            return None, f"too few features in reference frame {ref_index} ({len(ref.points_px)} < {cfg.sanity.min_features})"
        if self.matcher is None:
            pts_cur_all, ok = track_klt(ref_image, cur_image, ref.points_px, cfg.matching)
            idx_ref = np.flatnonzero(ok)
            cur = Features.fresh(pts_cur_all[idx_ref], None)
            idx_cur = np.arange(len(idx_ref))
        else:
            cur = Features.fresh(*self.detector.detect(cur_image))
            if len(cur.points_px) < cfg.sanity.min_features:
                return None, f"too few features ({len(cur.points_px)} < {cfg.sanity.min_features})"
            idx_ref, idx_cur = self.matcher(ref.descriptors, cur.descriptors)
        diag.n_matches = len(idx_ref)
        if len(idx_ref) < cfg.sanity.min_matches:
            return None, f"too few matches ({len(idx_ref)} < {cfg.sanity.min_matches})"
        pts_ref = ref.points_px[idx_ref]
        pts_cur = cur.points_px[idx_cur]
        # far points stand in for too few near ones (walking pace) where the checks reject a pure rotation, which
        # far points alone cannot tell from a translation under a guessed K
        est = estimate_two_view(pts_ref, pts_cur, self.K, cfg.geometry, min_inliers=cfg.sanity.min_inliers,
                                rng=None if cfg.seed is None else correspondence_rng(cfg.seed, j),
                                far_points=cfg.sanity.enabled)
        diag.method = est.method
        diag.n_inliers = est.n_inliers
        if est.ok:
            diag.rotation_deg = float(rotation_angle_deg(est.R_cur_ref))
            diag.parallax_px = est.parallax_px
        reason = check_pose(est, cfg.sanity)
        if reason is not None:
            if est.ok and _is_valid_rotation(est.R_cur_ref, cfg.sanity.max_rotation_deg):
                self._rejected_R_cur_ref = est.R_cur_ref
            elif reason.startswith(_NO_PARALLAX) and est.rotation_only_px < cfg.sanity.min_parallax_px:
                # no essential matrix (typical of a pure rotation) but a pure rotation explains the matches
                R = rotation_only_fit(normalize_points(pts_ref, self.K), normalize_points(pts_cur, self.K),
                                      float(self.K[0, 0]))[0]
                if _is_valid_rotation(R, cfg.sanity.max_rotation_deg):
                    self._rejected_R_cur_ref = R
            return None, reason

        gap = j - ref_index
        R, t = est.R_cur_ref, est.t_cur_ref
        inl = est.inliers
        X_ref = X_cur = angle = None
        if cfg.scale.mode == "gt":
            gt = self.ground_truth.poses_se3
            scale = float(np.linalg.norm(gt[j, :3, 3] - gt[ref_index, :3, 3]))
        elif cfg.scale.mode == "none":
            scale = float(max(gap - n_still, 1))
        else:
            X_ref, X_cur, angle = triangulate(R, t, normalize_points(pts_ref, self.K), normalize_points(pts_cur, self.K))
            tracked = self._track_scale_points(ref, ref_image, cur_image, R, t,
                                               None if cfg.seed is None else correspondence_rng(cfg.seed, j))
            if tracked is None:
                found, n_common = relative_scale(ref.depth[idx_ref], X_ref, angle, inl, cfg.scale)
            else:
                found, n_common = relative_scale(tracked.depth_ref, tracked.X_ref, tracked.angle_deg, tracked.usable,
                                                 cfg.scale, cfg.scale.corner_min_angle_deg)
            diag.n_scale_points = n_common
            moving = max(gap - n_still, 1)  # frame steps with motion, as run() counts them
            # only the first pair starts the scale silently; a later pair without depths (the reference was reset)
            # keeps the previous scale with a note
            decision = guarded_scale(None if found is None else found / moving, last_scale, n_common, first_pair,
                                     cfg.scale)
            scale = decision.scale * moving
            if decision.note:
                diag.note = decision.note
        diag.scale = scale
        if not np.isfinite(scale) or scale < 0:
            return None, f"invalid scale {scale}"

        T_cur_ref = np.eye(4)
        T_cur_ref[:3, :3] = R
        T_cur_ref[:3, 3] = t * scale
        if cfg.scale.mode == "relative":
            # with scale corners the features' depths only select the KLT tracks carried on: the corners' angle
            min_angle_deg = cfg.scale.min_triangulation_angle_deg if tracked is None else cfg.scale.corner_min_angle_deg
            good = inl & (X_cur[:, 2] > 0) & (X_ref[:, 2] > 0) & (angle >= min_angle_deg)
            cur.depth[idx_cur[good]] = X_cur[good, 2] * scale
            if tracked is not None:
                keep = tracked.usable & (tracked.X_cur[:, 2] > 0) & (tracked.X_ref[:, 2] > 0)
                keep &= tracked.angle_deg >= cfg.scale.corner_min_angle_deg
                keep = np.flatnonzero(keep)[: cfg.scale.max_carried_points]
                cur.scale_points_px = tracked.points_cur_px[keep]
                cur.scale_points_depth, cur.scale_points_views = self._fused_depths(
                    tracked, keep, tracked.R_cur_ref, tracked.t_cur_ref, scale)
        return (se3_inverse(T_cur_ref), cur, scale, (pts_ref[inl], pts_cur[inl])), ""

    def _fused_depths(self, tracked: TrackedScalePoints, keep: np.ndarray, R: np.ndarray, t: np.ndarray,
                      scale: float) -> tuple[np.ndarray, np.ndarray]:
        """Depths ``(K,)`` in the current frame of the kept scale points and their view counts ``(K,)``: the new
        triangulation averaged (in log) with the depth predicted from the reference depth and the scaled motion,
        weighted by the views behind it (at most ``scale.max_depth_views``): one pair's depth noise would otherwise
        pass straight into the next step's scale."""
        depth = tracked.X_cur[keep, 2] * scale
        views = np.ones(len(keep))
        depth_ref = tracked.depth_ref[keep]
        known = np.flatnonzero(np.isfinite(depth_ref))
        if len(known) == 0 or self.config.scale.max_depth_views <= 1:
            return depth, views
        ray = normalize_points(tracked.points_ref_px[keep][known], self.K)
        z_pred = np.column_stack([ray, np.ones(len(ray))]) @ R[2] * depth_ref[known] + t[2] * scale
        ahead = z_pred > 0
        idx = known[ahead]
        prior_views = np.minimum(tracked.views_ref[keep][idx], self.config.scale.max_depth_views - 1)
        w = prior_views / (prior_views + 1.0)
        depth[idx] = np.exp(w * np.log(z_pred[ahead]) + (1.0 - w) * np.log(depth[idx]))
        views[idx] = prior_views + 1.0
        return depth, views

    def _track_scale_points(self, ref: Features, ref_image: np.ndarray, cur_image: np.ndarray, R: np.ndarray,
                            t: np.ndarray, rng: np.random.Generator | None = None) -> TrackedScalePoints | None:
        """Scale points (``scale.points == "corners"``, pipelines other than KLT on corners): the reference's carried
        scale points plus fresh bucketed corners, followed into the current frame by KLT and triangulated
        (``usable``: tracked and within the epipolar threshold). ``scale.corner_pose == "corners"`` triangulates
        them with the pair's pose estimated again on the tracked corners (``_CORNER_GEOMETRY``; ``rng`` shuffles
        their order like the pipeline's correspondences), falling back to the pair's pose ``R, t`` when that
        estimate fails or has fewer than ``scale.min_common_points`` inliers. None when the pipeline's own
        correspondences carry the depths."""
        cfg = self.config
        if self._scale_detector is None:
            return None
        fresh = self._scale_detector.detect(ref_image)[0]
        if ref.scale_points_px is not None and len(ref.scale_points_px):
            pts_ref = np.concatenate([ref.scale_points_px, fresh]).astype(np.float32)
            depth_ref = np.concatenate([ref.scale_points_depth, np.full(len(fresh), np.nan)])
            views_ref = np.concatenate([ref.scale_points_views, np.zeros(len(fresh))])
        else:
            pts_ref, depth_ref = fresh.astype(np.float32), np.full(len(fresh), np.nan)
            views_ref = np.zeros(len(fresh))
        if len(pts_ref) == 0:
            return None
        pts_cur, ok = track_klt(ref_image, cur_image, pts_ref, cfg.matching)
        if cfg.scale.corner_pose == "corners":
            # an unrefined descriptor pose (report_orb: ORB + MAGSAC) is off by ~2 deg in translation direction,
            # which biases every triangulated depth the same way: its scale drifted ~17 % in 20 frames on KITTI 01
            est = estimate_two_view(pts_ref[ok], pts_cur[ok], self.K, _CORNER_GEOMETRY,
                                    min_inliers=cfg.scale.min_common_points, rng=rng)
            if est.ok and est.n_inliers >= cfg.scale.min_common_points:
                R, t = est.R_cur_ref, est.t_cur_ref
        n_ref, n_cur = normalize_points(pts_ref, self.K), normalize_points(pts_cur, self.K)
        X_ref, X_cur, angle = triangulate(R, t, n_ref, n_cur)
        residual_px = np.abs(sampson_residuals(skew(t) @ R, n_ref, n_cur)) * float(self.K[0, 0])
        usable = ok & (residual_px < cfg.geometry.threshold_px)
        return TrackedScalePoints(depth_ref, views_ref, pts_ref, pts_cur, X_ref, X_cur, angle, usable, R, t)

    def _standstill_motion(self) -> np.ndarray:
        """``T_ref_cur`` of a frame rejected for lack of parallax: no translation; the two-view rotation when it was
        valid, else the pure-rotation fit of the matches when it explains them, else identity."""
        T = np.eye(4)
        if self._rejected_R_cur_ref is not None:
            T[:3, :3] = self._rejected_R_cur_ref.T
        return T

    def _predicted_motion(self, step_motion: np.ndarray, j: int) -> np.ndarray:
        """Motion given to a frame rejected for any reason but lack of parallax: the last accepted per-frame motion
        (GT step length in ``gt`` mode), or identity with ``on_reject = "identity"``."""
        if self.config.on_reject == "identity":
            return np.eye(4)
        T = step_motion.copy()
        if self.config.scale.mode == "gt":
            gt = self.ground_truth.poses_se3
            norm = np.linalg.norm(T[:3, 3])
            step = float(np.linalg.norm(gt[j, :3, 3] - gt[j - 1, :3, 3]))
            T[:3, 3] = T[:3, 3] / norm * step if norm > 0 else 0.0
        return T


def intrinsics_mismatch(K: np.ndarray, image_shape: tuple[int, ...]) -> str | None:
    """Why ``K`` looks like the intrinsics of other images than these (its principal point off the image centre by
    more than a quarter of the image: half-size images with the full-size K ran without a word, APE fine, RPE 0.48 m
    a frame), or None."""
    h, w = image_shape[:2]
    cx, cy = float(K[0, 2]), float(K[1, 2])
    if abs(cx - (w - 1) / 2.0) <= 0.25 * w and abs(cy - (h - 1) / 2.0) <= 0.25 * h:
        return None
    return (f"the intrinsics' principal point ({cx:.1f}, {cy:.1f}) px is far from the centre of the {w} x {h} px images: "
            "intrinsics of other (e.g. full-size) images?")


def sequence_image_shape(images: Any, loaded: dict[int, tuple[np.ndarray | None, str]] | None = None
                         ) -> tuple[int, ...]:
    """Image shape of a sequence: the majority shape of its first readable frames (ties: the earliest), so one odd
    frame, even the first, cannot impose its size. ``loaded`` receives the frames read (``{index: (image | None,
    reason)}``). DataError when none of the first frames can be read."""
    read = images.read_image if hasattr(images, "read_image") else (lambda i: images[i])
    loaded = {} if loaded is None else loaded
    shapes: list[tuple[int, ...]] = []
    for i in range(min(len(images), _SIZE_PROBE)):
        loaded[i] = MonoVO._load(read, i)
        if loaded[i][0] is not None:
            shapes.append(loaded[i][0].shape)
            if len(shapes) == _SIZE_VOTES:
                break
    if not shapes:
        raise DataError(f"none of the first {len(loaded)} frames can be used ({_frames_by_reason(loaded)})",
                        source=getattr(images, "name", "images"))
    counts = Counter(shapes)
    shape = max(counts, key=lambda shape: (counts[shape], -shapes.index(shape)))
    if min(shape[:2]) < MIN_IMAGE_SIDE_PX:  # ORB and AKAZE asserted inside OpenCV (a traceback) on 200 x 1 px frames
        raise DataError(f"images of {shape[1]} x {shape[0]} px: too small for feature detection (at least "
                        f"{MIN_IMAGE_SIDE_PX} px a side)", source=getattr(images, "name", "images"))
    return shape


def _uint8_hint(dtype: np.dtype) -> str:
    """How to turn images of ``dtype`` into the uint8 ones the detectors take (lidarkit does not guess their range)."""
    if np.issubdtype(dtype, np.floating):
        return ("convert with e.g. np.clip(img, 0, 255).astype(np.uint8) for 0-255 floats, "
                "np.clip(img * 255, 0, 255).astype(np.uint8) for 0-1 ones")
    if np.issubdtype(dtype, np.integer):
        return ("convert with e.g. (img >> 8).astype(np.uint8) for 16-bit images, "
                "np.clip(img, 0, 255).astype(np.uint8) for 0-255 values")
    return "convert to uint8 grey levels 0-255"


def _frames_by_reason(loaded: dict[int, tuple[np.ndarray | None, str]]) -> str:
    """``frames 0-9: <reason>; frame 12: <other reason>``: each reason once, with the frames it applies to (ten float
    images repeated the same reason ten times, ~700 characters)."""
    frames_of: dict[str, list[int]] = {}
    for index, (_, reason) in sorted(loaded.items()):
        frames_of.setdefault(reason, []).append(index)
    return "; ".join(f"{'frames' if len(frames) > 1 else 'frame'} {index_runs(frames)}: {reason}"
                     for reason, frames in frames_of.items())


def _per_frame_motion(T_ref_cur: np.ndarray, gap: int) -> np.ndarray:
    """``T_ref_cur`` spread evenly over ``gap`` frames (geodesic fraction)."""
    if gap <= 1:
        return T_ref_cur.copy()
    return se3_fraction(T_ref_cur, gap)


def _is_valid_rotation(R: np.ndarray, max_deg: float) -> bool:
    """Finite, a rotation (orthonormal, det +1) and turning at most ``max_deg``."""
    return bool(np.all(np.isfinite(R))) and is_rotation(R, tol=1e-6) and float(rotation_angle_deg(R)) <= max_deg


def run_vo(images: Any, K: np.ndarray, config: VOConfig | None = None, ground_truth: Trajectory | None = None,
           **kwargs: Any) -> VOResult:
    """Convenience: ``MonoVO(config, K, ground_truth).run(images, **kwargs)``."""
    return MonoVO(config, K, ground_truth).run(images, **kwargs)


def images_in_memory(sequence: Any) -> list[np.ndarray | DataError]:
    """Read every image of an ``ImageSequence`` - for timing without disk I/O; an unreadable one is kept as its
    DataError, which :class:`MonoVO` rejects with that reason (None said "missing" for a file that was there)."""
    out: list[np.ndarray | DataError] = []
    for i in range(len(sequence)):
        try:
            out.append(sequence.read_image(i))
        except DataError as err:
            out.append(err)
    return out


__all__: Sequence[str] = ["FrameDiagnostics", "MonoVO", "TrackingFailedError", "VOResult", "images_in_memory",
                         "intrinsics_mismatch", "rejection_key", "run_vo", "sequence_image_shape"]
