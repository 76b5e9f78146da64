"""Numeric text tables (KITTI poses, TUM trajectories, calib files) read with line-numbered errors."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from lidarkit.atomic import missing_reason, stream_reason
from lidarkit.errors import DataError, LidarKitError


def read_lines(path: str | os.PathLike, what: str = "file") -> list[str]:
    """All lines of a text file (a UTF-8 byte-order mark, as some editors save, left out); a missing or unreadable
    file is a DataError naming it; ``what``: the kind of file expected, for the message about a folder given instead
    ("not a regular file" did not say what was wrong)."""
    path = Path(path)
    try:
        if not path.is_file():
            if path.is_dir():
                raise DataError(f"is a folder, not a {what}", source=path)
            reason = missing_reason(path, "file not found") if not path.exists() else stream_reason(path)
            raise DataError(reason or "not a regular file", source=path)
        return path.read_text(encoding="utf-8-sig").splitlines()
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
) -> np.ndarray:
    """Rows of ``ncols`` numbers (space- or comma-separated) as an ``(N, ncols)`` float64 array.

    Blank lines and lines starting with ``comment`` are skipped. A row with another number of
    fields, a non-number or (unless allowed) NaN/inf raises DataError naming file and line.
    ``ncols`` may be a tuple of accepted widths; the first row decides and all rows must agree. ``what``: as for
    :func:`read_lines`.
    """
    accepted = (ncols,) if isinstance(ncols, int) else tuple(ncols)
    rows: list[list[float]] = []
    width: int | None = None
    for lineno, raw in enumerate(read_lines(path, what), start=1):
        line = raw.strip()
        if not line or line.startswith(comment):
            continue
        fields = line.replace(",", " ").split()
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
            raise DataError(f"not a number: {bad!r}", source=path, location=f"line {lineno}") from None
        if not allow_nonfinite and not all(np.isfinite(values)):
            raise DataError("NaN or infinite value", source=path, location=f"line {lineno}")
        rows.append(values)
    if not rows:
        raise DataError("no data rows", source=path)
    return np.asarray(rows, dtype=np.float64)


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
    return [i for i, raw in enumerate(read_lines(path), start=1) if raw.strip() and not raw.strip().startswith("#")]


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
