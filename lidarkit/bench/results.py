"""Result files: one JSON per job under ``OUT/jobs/<key>.json``, written atomically by the parent process."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any

from lidarkit import atomic
from lidarkit.bench.jobs import Job, distinct_labels

log = logging.getLogger(__name__)

SCHEMA_VERSION = 1
JOBS_DIR = "jobs"


def path_argument(value: Any, argument: str) -> Path:
    """``value`` as a path; a ConfigError naming ``argument`` for anything else (None gave a TypeError from pathlib)."""
    from lidarkit.errors import ConfigError

    if not isinstance(value, (str, os.PathLike)):
        raise ConfigError(f"must be a path, got {type(value).__name__} {value!r}", source=argument)
    return Path(value)


def results_folder(path: str | os.PathLike) -> Path:
    """``path`` as a bench results folder (one with ``jobs/``); DataError saying it is missing or is another folder."""
    from lidarkit.atomic import missing_reason
    from lidarkit.errors import DataError

    path = Path(path)
    if not (path / JOBS_DIR).is_dir():
        if (path / "suite.json").is_file():  # a run stopped before its first job finished: a results folder all the same
            raise DataError("no job has finished in this results folder yet (its run stopped before the first): run the "
                            "suite again to resume", source=path)
        missing = "not a bench results folder (no jobs/ inside)" if path.exists() else missing_reason(path, "folder not found")
        raise DataError(missing, source=path)
    return path


def result_path(out_dir: Path, key: str) -> Path:
    return Path(out_dir) / JOBS_DIR / f"{key}.json"


def make_record(job: Job, key: str, version: str, outcome: dict[str, Any]) -> dict[str, Any]:
    """The full result record: schema, key, version, the job's resolved spec, then the worker's outcome."""
    return {"schema": SCHEMA_VERSION, "key": key, "lidarkit_version": version, "job": job.spec(), **outcome}


def write_result(out_dir: Path, record: dict[str, Any]) -> Path:
    """Write one record atomically (temp file + fsync + rename): a crash leaves it complete or absent."""
    text = json.dumps(record, indent=1, sort_keys=True, allow_nan=False)
    return atomic.write_text(result_path(out_dir, record["key"]), text + "\n")


def read_result(path: Path) -> dict[str, Any] | None:
    """A record, or None if the file is unreadable / not a result (logged)."""
    try:
        record = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        log.warning("ignoring unreadable result %s: %s", path, err)
        return None
    if not isinstance(record, dict) or record.get("schema") != SCHEMA_VERSION or "job" not in record:
        log.warning("ignoring %s: not a lidarkit bench result", path)
        return None
    problem = malformed(record)
    if problem:
        log.warning("ignoring %s: %s", path, problem)
        return None
    return record


def malformed(record: dict[str, Any]) -> str:
    """Why a result record cannot be read (edited by hand, or written by another lidarkit version), or ''."""
    from dataclasses import fields

    job = record["job"]
    if not isinstance(job, dict):
        return f"'job' is {type(job).__name__}, not a mapping"
    names = {f.name for f in fields(Job)}
    if set(job) != names:
        missing, extra = sorted(names - set(job)), sorted(set(job) - names)
        return "job " + "; ".join(x for x in (f"lacks {', '.join(missing)}" if missing else "",
                                                f"has unknown {', '.join(extra)}" if extra else "") if x)
    for key in ("task", "experiment", "dataset_name", "method"):
        if not isinstance(job[key], str):
            return f"job {key} is {job[key]!r}, not text"
    for key in ("dataset", "params", "options"):
        if not isinstance(job[key], dict):
            return f"job {key} is {job[key]!r}, not a mapping"
    if not isinstance(job["seed"], int) or isinstance(job["seed"], bool):
        return f"job seed is {job['seed']!r}, not an integer"
    if not isinstance(record.get("status"), str):
        return f"status is {record.get('status')!r}, not text"
    metrics = record.get("metrics", {})
    if not isinstance(metrics, dict):
        return f"metrics is {metrics!r}, not a mapping"
    for name, value in metrics.items():  # tasks write numbers (None: not defined for this run)
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))):
            return f"metric {name} is {value!r}, not a number"
    runtime = record.get("runtime_s")
    if runtime is not None and (isinstance(runtime, bool) or not isinstance(runtime, (int, float))):
        return f"runtime_s is {runtime!r}, not a number"
    warnings = record.get("warnings", [])
    if warnings is not None and (not isinstance(warnings, list) or not all(isinstance(w, str) for w in warnings)):
        return f"warnings is {warnings!r}, not a list of text"
    if record.get("error") is not None and not isinstance(record["error"], dict):
        return f"error is {record['error']!r}, not a mapping"
    return ""


def is_finished(out_dir: Path, key: str) -> bool:
    """True when a readable, successful result exists for ``key`` (failed jobs are retried on resume)."""
    path = result_path(out_dir, key)
    if not path.exists():
        return False
    record = read_result(path)
    return record is not None and record.get("status") == "ok"


def load_results(out_dir: Path) -> list[dict[str, Any]]:
    """Every readable record under ``out_dir`` sorted by (task, experiment, dataset, method, params, seed)."""
    files = sorted(p for p in (Path(out_dir) / JOBS_DIR).glob("*.json") if not p.name.startswith("."))
    records = [r for r in (read_result(p) for p in files) if r is not None]

    def order(r: dict[str, Any]) -> tuple:
        j = r["job"]
        return (j["task"], j["experiment"], j["dataset_name"], j["method"], json.dumps(j["params"], sort_keys=True), j["seed"])

    return sorted(records, key=order)


def dataset_labels(records: list[dict[str, Any]]) -> dict[int, str]:
    """Each record's dataset label (by ``id``), told apart where different datasets or task options share one
    (two unnamed simulated scenes, a folder reused after a suite's options changed)."""
    labels = [r["job"]["dataset_name"] for r in records]
    specs = [{**r["job"]["dataset"], **r["job"]["options"]} for r in records]
    return dict(zip(map(id, records), distinct_labels(labels, specs)))


def ground_truth_instant(record: dict[str, Any]) -> str:
    """The sweep instant an odometry record's reference refers to ("sweep end"), as its run stated it; '' if none."""
    effective = (((record.get("info") or {}).get("odometry_metrics") or {}).get("effective") or {})
    instant = str(effective.get("ground_truth_instant") or "")
    return f"sweep {instant}" if instant in ("start", "mid", "end") else instant


def remove_stale_temp_files(out_dir: Path, older_than_s: float = 600.0) -> int:
    """Delete temp files a killed run left in ``jobs/`` (``.<key>.*.json``, never read as results); return the count."""
    import time

    removed = 0
    for path in (Path(out_dir) / JOBS_DIR).glob(".*.json"):
        try:
            if time.time() - path.stat().st_mtime > older_than_s:
                path.unlink()
                removed += 1
        except OSError:
            pass
    return removed
