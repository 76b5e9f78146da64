"""A benchmark job: one (task, dataset, method, params, seed) and its content-addressed key."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from typing import Any


def canonical_json(value: Any) -> str:
    """JSON with sorted keys and no whitespace: equal specs give byte-equal strings."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)


def whole_floats_as_ints(value: Any) -> Any:
    """``value`` with every whole float an int (``1.0`` -> ``1``), through mappings and lists: one number written two
    ways is one job. Ints, other floats, text and booleans are left as they are, so a spec without a whole float keys
    as it always did; text stays text ("1" and "1.0" are two values of a text parameter)."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    if isinstance(value, dict):
        return {k: whole_floats_as_ints(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [whole_floats_as_ints(v) for v in value]
    return value


@dataclass(frozen=True)
class Job:
    """Everything a worker needs to run one experiment instance; plain data so it pickles cheaply.

    ``dataset`` is the resolved dataset spec (absolute paths or ``sample:NAME``); ``options`` are task
    options shared by the experiment (e.g. frame range); ``experiment`` and ``dataset_name`` are labels.
    """

    task: str
    experiment: str
    dataset_name: str
    dataset: dict[str, Any]
    method: str
    params: dict[str, Any] = field(default_factory=dict)
    seed: int = 0
    options: dict[str, Any] = field(default_factory=dict)

    def spec(self) -> dict[str, Any]:
        """The job as a JSON-ready dict (what the key hashes and the result file records)."""
        return asdict(self)

    @classmethod
    def from_spec(cls, spec: dict[str, Any]) -> Job:
        return cls(**spec)

    def key(self, version: str | None = None) -> str:
        """Hex key from the canonical spec and the code's version (:func:`lidarkit.provenance.code_version`: the
        release and a digest of the source): same job, same code -> same key. Whole floats count as ints
        (``noise_m: 1.0`` and ``noise_m: 1`` are one job: an edited suite reran every job, two report rows with one
        label); a spec without one keys as before, its results kept on resume."""
        if version is None:
            from lidarkit.provenance import code_version

            version = code_version()
        payload = canonical_json({"job": whole_floats_as_ints(self.spec()), "lidarkit_version": version})
        return hashlib.sha256(payload.encode("ascii")).hexdigest()[:20]

    @property
    def method_label(self) -> str:
        """``method(p=v, ...)`` with params sorted: the row label in reports."""
        return method_label(self.method, self.params)


def method_label(method: str, params: dict[str, Any]) -> str:
    """``method(p=v, ...)`` with ``params`` sorted (``method`` alone without any)."""
    if not params:
        return method
    inner = ", ".join(f"{k}={_short(v)}" for k, v in sorted(params.items()))
    return f"{method}({inner})"


def _short(value: Any) -> str:
    """A value as labels show it: floats in ``:g`` form unless that reads as another number (0.5000001)."""
    if isinstance(value, float):
        text = f"{value:g}"
        return text if float(text) == value else repr(value)
    return str(value)


def distinct_labels(labels: list[str], specs: list[dict[str, Any]]) -> list[str]:
    """``labels`` made unique: labels shared by different ``specs`` get the fields those specs differ in,
    ``sim_lidar(scene=open)``, so that a report never pools two datasets as if they were seeds of one. A field a spec
    does not set is left out of its label, as :func:`method_label` leaves out unset params (it read ``init_noise_m=None``
    where the option's default is 0)."""
    def text(value: Any) -> str:  # (values that are not plain JSON are refused later, naming the suite's line)
        return json.dumps(value, sort_keys=True, default=repr)

    out = list(labels)
    groups: dict[str, list[int]] = {}
    for i, label in enumerate(labels):
        groups.setdefault(label, []).append(i)
    for label, group in groups.items():
        if len(group) < 2 or len({text(specs[i]) for i in group}) < 2:
            continue
        keys = sorted({k for i in group for k in specs[i]})
        differing = [k for k in keys if len({text(specs[i].get(k)) for i in group}) > 1]
        for i in group:
            inner = ", ".join(f"{k}={_short(specs[i][k])}" for k in differing if k in specs[i])
            out[i] = f"{label}({inner})" if inner else label
    return out
