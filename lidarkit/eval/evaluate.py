"""One call that scores an estimate every standard way: APE and RPE (translation and rotation), KITTI drift."""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from lidarkit.errors import ConfigError
from lidarkit.eval.ape_rpe import (
    APEResult,
    RPEResult,
    ape,
    check_align_name,
    check_flags,
    check_legacy_pairs,
    checked_delta,
    rpe,
)
from lidarkit.eval.kitti_drift import (
    KITTI_LENGTHS_M,
    KITTI_STEP_FRAMES,
    DriftResult,
    checked_lengths,
    checked_step,
    drift_segments_possible,
    kitti_drift,
    path_distances_m,
)
from lidarkit.eval.pairing import association_warning, check_max_diff, pair_name, paired, stamps_disagree
from lidarkit.trajectory import READ_WARNINGS, Trajectory

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class EvaluationSettings:
    """Settings of :func:`evaluate` with their defaults (the CLI's defaults come from here).

    ``align`` applies to APE and RPE (a rigid alignment does not change RPE; ``sim3`` rescales it).
    ``drift``: compute the KITTI drift when the reference path is longer than the shortest segment length.
    """

    align: str = "se3"
    delta: float = 1
    delta_unit: str = "frames"
    all_pairs: bool = False
    pairs_from_reference: bool = False
    legacy_pairs: bool = False
    associate: bool = False
    max_diff_s: float = 0.01
    drift: bool = True
    drift_lengths_m: tuple[float, ...] = KITTI_LENGTHS_M
    drift_step_frames: int = KITTI_STEP_FRAMES

    def __post_init__(self) -> None:
        """Switches that are True or False, an RPE delta evo accepts (200 deg failed after the drift), legacy pairs only
        for consecutive path/angle pairs (refused by rpe() after pairing and the drift), and drift segment
        lengths that are positive numbers (an empty tuple or a single number was a traceback; "false" computed the drift)."""
        check_align_name(self.align)  # (align="xyz" was refused only by evaluate())
        _, unit = checked_delta(self.delta, self.delta_unit)
        checked_step(self.drift_step_frames, "drift_step_frames")
        check_flags(all_pairs=self.all_pairs, pairs_from_reference=self.pairs_from_reference, legacy_pairs=self.legacy_pairs,
                    associate=self.associate, drift=self.drift)
        check_legacy_pairs(self.legacy_pairs, unit, self.all_pairs)
        check_max_diff(self.max_diff_s)  # (also bounds the stamp check without associate: None was a TypeError there)
        checked_lengths(self.drift_lengths_m, "drift_lengths_m", "drift segment lengths")
        for name, value in vars(self).items():  # numpy scalars as plain numbers: to_dict() is for JSON (np.int64 was not)
            if isinstance(value, np.generic):
                object.__setattr__(self, name, value.item())

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["drift_lengths_m"] = [float(x) for x in self.drift_lengths_m]
        return out


@dataclass(frozen=True, eq=False)
class Evaluation:
    """APE/RPE in translation (m) and rotation (deg), and KITTI drift (None with ``drift_note`` if skipped).

    ``ref_length_m`` is the whole reference's path; ``scored_path_m`` the part of it between the first and last pose
    scored (the same without ``associate``), both measured along the whole reference.
    """

    ref_name: str
    est_name: str
    n_poses: int
    ref_length_m: float
    scored_path_m: float
    settings: EvaluationSettings
    ape: APEResult
    ape_rotation: APEResult
    rpe: RPEResult
    rpe_rotation: RPEResult
    drift: DriftResult | None
    drift_note: str = ""
    warnings: tuple[str, ...] = ()
    """What the files' readers (poses left out: ``Trajectory.meta["read_warnings"]``) and the pairing (few poses
    associated, or stamps paired by index that disagree) warned of, as logged."""

    def __repr__(self) -> str:
        """One line of the headline figures (the generated one printed every field of every result: ~4900 characters)."""
        drift = (f"drift {self.drift.translation_pct:.4g} % / {self.drift.rotation_deg_per_100m:.4g} deg/100m"
                 if self.drift is not None else f"no drift ({self.drift_note})")
        poses = (f"{self.n_poses} associated poses over {self.scored_path_m:.4g} m of a {self.ref_length_m:.4g} m reference"
                 if self.settings.associate else f"{self.n_poses} poses over {self.ref_length_m:.4g} m")
        return (f"Evaluation({self.est_name!r} against {self.ref_name!r}, {poses}: "
                f"APE rmse {self.ape.rmse:.4g} m / {self.ape_rotation.rmse:.4g} deg ({self.ape.align}), RPE rmse "
                f"{self.rpe.rmse:.4g} m / {self.rpe_rotation.rmse:.4g} deg per {self.rpe.delta:g} {self.rpe.delta_unit}, {drift})")

    def to_dict(self, include_errors: bool = False) -> dict[str, Any]:
        """JSON-safe dict, with what the pairing warned of; per-pose error arrays only with ``include_errors``."""
        return {
            "ref_name": self.ref_name,
            "est_name": self.est_name,
            "n_poses": self.n_poses,
            "ref_length_m": self.ref_length_m,
            "scored_path_m": self.scored_path_m,
            "settings": self.settings.to_dict(),
            "ape": self.ape.to_dict(include_errors),
            "ape_rotation": self.ape_rotation.to_dict(include_errors),
            "rpe": self.rpe.to_dict(include_errors),
            "rpe_rotation": self.rpe_rotation.to_dict(include_errors),
            "kitti_drift": None if self.drift is None else self.drift.to_dict(),
            "kitti_drift_note": self.drift_note,
            "warnings": list(self.warnings),
        }


def evaluate(ref: Trajectory, est: Trajectory, settings: EvaluationSettings | None = None, **overrides) -> Evaluation:
    """Score ``est`` against ``ref`` with ``settings`` (or ``EvaluationSettings(**overrides)``)."""
    if settings is None:
        try:
            settings = EvaluationSettings(**overrides)
        except TypeError as err:
            raise ConfigError(f"unknown evaluation setting: {err}", source="evaluate") from None
    elif overrides:
        raise ConfigError("pass either settings or keyword overrides, not both", source="evaluate")
    elif not isinstance(settings, EvaluationSettings):  # (a dict: an AttributeError deep inside)
        raise ConfigError(f"settings must be an EvaluationSettings (or pass them as keywords), got {type(settings).__name__}",
                          source="evaluate")
    s = settings
    # pair (and, with ``associate``, match timestamps) once; the metrics then get equal-length trajectories
    ref_paired, est_paired = paired(ref, est, associate=s.associate, max_diff_s=s.max_diff_s)
    if s.associate:  # (paired() logged it)
        warned = association_warning(ref, est, ref_paired, s.max_diff_s)
    elif warned := stamps_disagree(ref, est, s.max_diff_s):
        logger.warning("%s: %s", pair_name(ref, est), warned)
    rpe_kw = dict(
        delta=s.delta,
        delta_unit=s.delta_unit,
        all_pairs=s.all_pairs,
        align=s.align,
        pairs_from_reference=s.pairs_from_reference,
        legacy_pairs=s.legacy_pairs,
    )
    # path distances along the whole reference: the line through sparse associated poses cuts its corners
    whole_ref = ref if s.associate else None
    distances = path_distances_m(ref_paired, whole_ref)
    scored_path_m = ref.length_m if whole_ref is None else float(distances[-1] - distances[0])
    drift, note = None, ""
    if not s.drift:
        note = "not requested"
    elif drift_segments_possible(ref_paired, s.drift_lengths_m, path_along=whole_ref):
        # (quiet as APE and RPE are: a coordinate of 1e300 printed numpy's overflow warnings here before the RPE below
        # refused the pair in one line)
        with np.errstate(over="ignore", invalid="ignore"):
            drift = kitti_drift(ref_paired, est_paired, s.drift_lengths_m, s.drift_step_frames, path_along=whole_ref)
    elif s.associate:
        note = (f"the associated poses span {scored_path_m:.1f} m of the {ref.length_m:.1f} m reference path, not longer "
                f"than {min(s.drift_lengths_m):g} m")
    else:
        note = f"reference path {ref.length_m:.1f} m is not longer than {min(s.drift_lengths_m):g} m"
    if note:
        logger.info("KITTI drift skipped: %s", note)
    translation = rpe(ref_paired, est_paired, relation="translation", **rpe_kw)
    return Evaluation(
        ref_name=ref.name,
        est_name=est.name,
        n_poses=len(ref_paired),
        ref_length_m=ref.length_m,
        scored_path_m=scored_path_m,
        settings=s,
        ape=_marked(ape(ref_paired, est_paired, s.align, "translation"), s.associate),
        ape_rotation=_marked(ape(ref_paired, est_paired, s.align, "rotation_angle_deg"), s.associate),
        rpe=_marked(translation, s.associate),
        # the same pairs: evo's all-pairs search over a path or angle delta is quadratic in the poses
        rpe_rotation=_marked(rpe(ref_paired, est_paired, relation="rotation_angle_deg", pairs=translation.pairs, **rpe_kw), s.associate),
        drift=drift,
        drift_note=note,
        warnings=tuple(dict.fromkeys([*_read_warnings(ref), *_read_warnings(est), *([warned] if warned else [])])),
    )


def _read_warnings(trajectory: Trajectory) -> list[str]:
    """What the reader of ``trajectory``'s file warned of (a scored trajectory with poses left out read clean)."""
    return [str(w) for w in (trajectory.meta or {}).get(READ_WARNINGS, ())]


def _marked(result, associated: bool):
    """``result`` of a metric run on already-associated trajectories, flagged as associated like a direct call."""
    return replace(result, associated=True) if associated else result
