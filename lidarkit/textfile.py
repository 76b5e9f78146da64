"""Numeric text tables (KITTI poses, TUM trajectories, calib files) read with line-numbered errors."""

from __future__ import annotations

import logging
import os
import re
from pathlib import Path

import numpy as np

from lidarkit.atomic import missing_reason, stream_reason
from lidarkit.errors import DataError, LidarKitError

log = logging.getLogger(__name__)

#: other lines of the same kind a cut-off last line is compared with (fewer: no warning, too little to go by)
CUT_CHECK_MIN_PEERS = 2
_EXPONENT = re.compile(r"[eE][+-]?(\d*)$")


def read_lines(path: str | os.PathLike, what: str = "file", *, warnings: list[str] | None = None,
               check_cut: bool = True) -> list[str]:
    """All lines of a text file (a UTF-8 byte-order mark, as some editors save, left out); a missing or unreadable
    file is a DataError naming it; ``what``: the kind of file expected, for the message about a folder given instead
    ("not a regular file" did not say what was wrong).

    A last line without a line end whose last number looks cut against the other lines (:func:`cut_off_reason`) is
    logged as a warning, also appended to ``warnings`` when given (a file cut inside its last number read silently:
    a path's length four times the truth); ``check_cut=False`` for a file read again only to number its lines."""
    path = Path(path)
    try:
        if not path.is_file():
            if path.is_dir():
                raise DataError(f"is a folder, not a {what}", source=path)
            reason = missing_reason(path, "file not found") if not path.exists() else stream_reason(path)
            raise DataError(reason or "not a regular file", source=path)
        text = path.read_text(encoding="utf-8-sig")
        lines = text.splitlines()
        if check_cut and text and not text.endswith(("\n", "\r")):
            reason = cut_off_reason(lines)
            if reason:
                log.warning("%s: %s", path, reason)
                if warnings is not None:
                    warnings.append(f"{path}: {reason}")
        return lines
    except OSError as err:  # (its own text repeats the path the message names already)
        raise DataError(f"cannot read it: {(err.strerror or type(err).__name__).lower()}", source=path) from err
    except UnicodeDecodeError as err:
        raise DataError(f"cannot read as text ({err.__class__.__name__}: {err})", source=path) from err


def read_numeric_table(
    path: str | os.PathLike,
    ncols: int | tuple[int, ...],
    *,
    comment: str = "#",
    allow_nonfinite: bool = False,
    what: str = "file",
    warnings: list[str] | None = None,
) -> np.ndarray:
    """Rows of ``ncols`` numbers (space- or comma-separated) as an ``(N, ncols)`` float64 array.

    Blank lines and lines starting with ``comment`` are skipped. A row with another number of
    fields, a non-number or (unless allowed) NaN/inf raises DataError naming file and line.
    ``ncols`` may be a tuple of accepted widths; the first row decides and all rows must agree. ``what`` and
    ``warnings`` (a cut-off last line): as for :func:`read_lines`.
    """
    accepted = (ncols,) if isinstance(ncols, int) else tuple(ncols)
    rows: list[list[float]] = []
    width: int | None = None
    for lineno, raw in enumerate(read_lines(path, what, warnings=warnings), start=1):
        line = raw.strip()
        if not line or line.startswith(comment):
            continue
        fields = line.replace(",", " ").split()
        # a date and time read "expected 1 number, found 2"; other lines of another count (a cut one) keep that message
        if len(fields) not in ((width,) if width is not None else accepted):
            _check_dates(fields, path, lineno)
        if width is None:
            if len(fields) not in accepted:
                want = " or ".join(str(n) for n in accepted)
                raise DataError(f"expected {want} number{'' if accepted == (1,) else 's'}, found {len(fields)}", source=path,
                                location=f"line {lineno}")
            width = len(fields)
        elif len(fields) != width:
            raise DataError(f"expected {width} number{'' if width == 1 else 's'}, found {len(fields)}", source=path,
                            location=f"line {lineno}")
        try:
            values = [float(f) for f in fields]
        except ValueError:
            bad = next(f for f in fields if not is_number(f))
            _check_dates([bad], path, lineno)
            raise DataError(f"not a number: {bad!r}", source=path, location=f"line {lineno}") from None
        if not allow_nonfinite and not all(np.isfinite(values)):
            raise DataError("NaN or infinite value", source=path, location=f"line {lineno}")
        rows.append(values)
    if not rows:
        raise DataError("no data rows", source=path)
    return np.asarray(rows, dtype=np.float64)


#: a date (2011-09-26) or a clock time (13:02:25.96) in a field
_DATE_OR_TIME = re.compile(r"\d{4}-\d{1,2}-\d{1,2}|\d{1,2}:\d{2}")


def _check_dates(fields: list[str], path: str | os.PathLike, lineno: int) -> None:
    """DataError naming the first of a line's ``fields`` that is a date or clock time and no number: seconds are
    wanted (KITTI raw's timestamps.txt given as a times file read "expected 1 number, found 2")."""
    dated = next((f for f in fields if _DATE_OR_TIME.search(f) and not is_number(f)), None)
    if dated is not None:
        raise DataError(f"not a number: {dated!r} (date/time stamps: give seconds, e.g. read KITTI raw's timestamps.txt "
                        "with lidarkit.io.kitti_raw.read_kitti_raw_timestamps)", source=path, location=f"line {lineno}")


def cut_off_reason(lines: list[str], comment: str = "#") -> str | None:
    """Why the last of ``lines`` (a file's, which has no line end) looks cut inside its last number, or None.

    It is compared with the other data lines of its kind (as many fields, the same leading word unless a number or a
    ``key:`` label): cut when its last value is shorter than that column's on every other line while its other values
    are not all shorter than theirs (a matrix's ``0 0 0 1`` row is no cut), or when every other line writes an
    exponent of n digits there and it has none or fewer. Writers end such files with a newline; a hand-written file
    without one is no reason to warn."""
    last = lines[-1].strip() if lines else ""
    if not last or last.startswith(comment):
        return None
    fields = _fields(last)
    if not is_number(fields[-1]):
        return None
    kind = _kind(fields)
    peers = [f for f in (_fields(raw) for raw in lines[:-1] if raw.strip() and not raw.strip().startswith(comment))
             if len(f) == len(fields) and _kind(f) == kind]
    if len(peers) < CUT_CHECK_MIN_PEERS:
        return None
    lengths = np.array([[len(value) for value in f] for f in peers])  # (peers, fields)
    shortest = lengths.min(axis=0)
    line = f"line {len(lines)} has no line end and its last value {fields[-1]}"
    others_shorter = all(len(value) < least for value, least in zip(fields[:-1], shortest[:-1], strict=True))
    if len(fields[-1]) < shortest[-1] and (len(fields) == 1 or not others_shorter):
        return f"{line} is shorter than that column's on every other line: the file may be cut off"
    exponents = {len(m.group(1)) if m else -1 for m in (_EXPONENT.search(f[-1]) for f in peers)}
    if len(exponents) == 1 and (digits := exponents.pop()) > 0:
        mine = _EXPONENT.search(fields[-1])
        if mine is None or len(mine.group(1)) < digits:
            return (f"{line} lacks the {digits}-digit exponent that column has on every other line: the file may be "
                    "cut off")
    return None


def _fields(line: str) -> list[str]:
    return line.replace(",", " ").split()


def _kind(fields: list[str]) -> str | None:
    """A record's leading word (``SENSOR``, ``ODOMETRY``); None for a number or a ``P0:`` label (calib lines)."""
    head = fields[0]
    return None if is_number(head) or head.endswith(":") else head.upper()


def is_number(text: str) -> bool:
    """True if ``text`` parses as a float."""
    try:
        float(text)
    except ValueError:
        return False
    return True


def data_line_numbers(path: str | os.PathLike) -> list[int]:
    """The file line (from 1) of each row ``read_numeric_table`` reads from ``path`` (blank and ``#`` lines skipped
    as the reader skips them)."""
    return [i for i, raw in enumerate(read_lines(path, check_cut=False), start=1)
            if raw.strip() and not raw.strip().startswith("#")]


def file_line(path: str | os.PathLike, location: str | None) -> str | None:
    """``"frame K"`` of a table read by ``read_numeric_table`` -> ``"line L, frame K"`` of ``path`` (in an error's
    parentheses: "(line 3, frame 2)"); other locations unchanged."""
    if not location or not location.startswith("frame "):
        return location
    try:
        k = int(location.split()[1])
        return f"line {data_line_numbers(path)[k]}, {location}"
    except (ValueError, IndexError, LidarKitError):
        return location
