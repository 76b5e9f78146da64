"""A benchmark job: one (task, dataset, method, params, seed) and its content-addressed key."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from typing import Any


def canonical_json(value: Any) -> str:
    """JSON with sorted keys and no whitespace: equal specs give byte-equal strings."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)


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
        """Hex key from the canonical spec and the lidarkit version: same job, same version -> same key."""
        if version is None:
            from lidarkit import __version__ as version
        payload = canonical_json({"job": self.spec(), "lidarkit_version": version})
        return hashlib.sha256(payload.encode("ascii")).hexdigest()[:20]

    @property
    def method_label(self) -> str:
        """``method(p=v, ...)`` with params sorted: the row label in reports."""
        if not self.params:
            return self.method
        inner = ", ".join(f"{k}={_short(v)}" for k, v in sorted(self.params.items()))
        return f"{self.method}({inner})"


def _short(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)
