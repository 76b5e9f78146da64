"""The output layer: every file and folder lidarkit writes goes through here.

- Files are written atomically (a temporary file beside the target, fsync, one rename): complete or absent. A target
  that is a stream (``/dev/null``, ``/dev/stdout``, a FIFO) is written into once the output is complete, not replaced.
- Run folders are all-or-nothing (:func:`run_folder`): written under a temporary hidden name and renamed into
  place only once every file is there, so a failed or killed run never leaves a folder that looks finished; into an
  existing folder the files are moved one rename each with SIGINT / SIGTERM / SIGHUP held until the last is in.
- Input paths that cannot be followed say why (:func:`resolved_path`, :func:`missing_reason`, :func:`stream_reason`): a loop
  of symbolic links or a link to a missing file is not "not found", a pipe is not "not a regular file".
- Any ``OSError`` (a file where a folder is needed, a folder where a file is needed, read-only file system,
  disk full, permission denied) and an unknown plot format become :class:`OutputError` naming the path.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import signal
import tempfile
import threading
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

from lidarkit.errors import ConfigError, DataError, OutputError
from lidarkit.lifetime import STOP_SIGNALS

try:  # advisory locks mark the temporary folders of outputs being written (POSIX)
    import fcntl
except ImportError:
    fcntl = None

__all__ = ["OutputError", "atomic_path", "ensure_dir", "missing_reason", "output_errors", "resolved_path", "run_folder",
           "save_figure", "stream_reason", "write_bytes", "write_text", "write_texts"]

_UMASK = os.umask(0o022)
os.umask(_UMASK)  # read once at import: os.umask can only be read by setting it

PARTIAL_MARK = ".partial-"  # temporary run folders: ``.<name>.partial-XXXX`` beside the final one
_RANDOM_CHARS = 8  # tempfile's random part of a name
_NAME_MAX = 255  # bytes in one name on the file systems lidarkit writes to (ext4, xfs, btrfs, tmpfs)
#: the files that say a folder holds a finished run or export: moved into an existing folder last (an earlier run's
#: first out of it); ``lidarkit compare`` takes a folder with a metrics.json for a finished run
_FINISHING = ("config.yaml", "config.json", "sim.yaml", "manifest.json", "metrics.json")

_REASONS = {
    errno.EEXIST: "a file is in the way (a folder is needed here)",
    errno.ENOTDIR: "a file is in the way (a folder is needed here)",
    errno.EISDIR: "is a folder (a file name is needed here)",
    errno.EROFS: "read-only file system",
    errno.ENOSPC: "no space left on the device",
    errno.EDQUOT: "disk quota exceeded",
    errno.EACCES: "permission denied",
    errno.EPERM: "permission denied",
    errno.EFBIG: "file too large for the file system",
    errno.ENAMETOOLONG: "file name too long",
    errno.ENOTEMPTY: "a non-empty folder is in the way",
}


def _reason(err: OSError) -> str:
    return _REASONS.get(err.errno, err.strerror or str(err))


def error_for(path: str | os.PathLike, err: OSError, what: str = "cannot write") -> OutputError:
    """The OutputError for an ``OSError`` met while writing ``path``."""
    return OutputError(f"{what}: {_reason(err)}", source=path)


@contextlib.contextmanager
def output_errors(path: str | os.PathLike, what: str = "cannot write") -> Iterator[None]:
    """Turn any ``OSError`` raised inside the block into an :class:`OutputError` naming ``path``."""
    try:
        yield
    except OutputError:
        raise
    except OSError as err:
        raise error_for(path, err, what) from err


def ensure_dir(path: str | os.PathLike) -> Path:
    """Create the folder ``path`` (and its parents) if needed; a file in the way is an OutputError."""
    path = Path(path)
    if path.is_dir():
        return path
    culprit = next((p for p in (path, *path.parents) if p.exists() and not p.is_dir()), None)
    if culprit is not None:
        raise OutputError("cannot create the folder: a file is in the way (a folder is needed here)", source=culprit)
    with output_errors(path, "cannot create the folder"):
        path.mkdir(parents=True, exist_ok=True)
    return path


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path`` in one rename.

    The temporary name keeps the suffix so writers that pick a format by extension
    (matplotlib, numpy, Open3D) still work. An ``OSError`` inside the block or while
    renaming becomes an OutputError naming ``path``. A ``path`` that is a symbolic link is written where it points (the
    rename replaced the link with a plain file and left the file it names as it was).
    """
    named = Path(path)
    if _is_stream(named):  # a stream has no contents to keep: the output is copied into it when complete (renamed
        yield from _through_temporary(named)  # over, /dev/null became a plain file; a PNG writer needs to seek)
        return
    path = Path(os.path.realpath(named)) if named.is_symlink() else named
    if path.is_dir():
        raise OutputError("cannot write: is a folder (a file name is needed here)", source=named)
    ensure_dir(path.parent)
    with output_errors(named):
        extra = 2 + _RANDOM_CHARS + len(os.fsencode(path.suffix))  # ".<stem>.XXXXXXXX<suffix>"
        # without a suffix, ".<stem>-XXXXXXXX": a dot before the random part read as one (a plot path "fig" was refused
        # after the work as of format ".nrp562oi")
        stem, dot = (path.stem, ".") if path.suffix else (path.stem.lstrip("."), "-")
        fd, tmp = tempfile.mkstemp(prefix=f".{temporary_stem(stem, extra)}{dot}", suffix=path.suffix, dir=path.parent)
        os.close(fd)
    tmp_path = Path(tmp)
    try:
        with output_errors(named):
            os.chmod(tmp_path, 0o666 & ~_UMASK)  # mkstemp creates 0600; results should get the usual permissions
            yield tmp_path
            os.replace(tmp_path, path)
    finally:
        with contextlib.suppress(OSError):
            tmp_path.unlink()


def _through_temporary(stream: Path) -> Iterator[Path]:
    """Yield a temporary file (the system's temporary folder, ``stream``'s suffix); when the block ends, copy it into
    ``stream`` (opened by its name: /dev/stdout reaches the pipe it stands for)."""
    import shutil

    with output_errors(stream):
        fd, tmp = tempfile.mkstemp(prefix=".lidarkit-", suffix=stream.suffix)
        os.close(fd)
    try:
        with output_errors(stream):
            yield Path(tmp)
            with open(tmp, "rb") as src, open(stream, "wb") as dst:
                shutil.copyfileobj(src, dst)
    finally:
        with contextlib.suppress(OSError):
            os.unlink(tmp)


def _is_stream(path: Path) -> bool:
    """Whether ``path`` is an existing character device or FIFO, through any links (written into: ``--json
    /dev/null``, ``/dev/stdout``); an OutputError for other special files (a block device, a socket): not outputs."""
    import stat

    try:
        mode = path.stat().st_mode
    except OSError:
        return False
    if stat.S_ISCHR(mode) or stat.S_ISFIFO(mode):
        return True
    if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        raise OutputError("cannot write: not a regular file (a block device or a socket)", source=path)
    return False


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` atomically; return the path."""
    return write_bytes(path, _utf8(text, path, "write_text"))


def write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; return the path."""
    try:  # bytes or any buffer (an array's memory); a str was a TypeError from the file's write
        memoryview(data)
    except TypeError:
        hint = " (write_text writes a str)" if isinstance(data, str) else ""
        raise ConfigError(f"write_bytes: data must be bytes, got {type(data).__name__}{hint}", source=path) from None
    with atomic_path(path) as tmp:
        _write_synced(tmp, data)
    return Path(path)


def _utf8(text: str, path: str | os.PathLike, caller: str) -> bytes:
    """``text`` encoded for writing, or a ConfigError naming its type (bytes had no ``encode``: an AttributeError)."""
    if not isinstance(text, str):
        hint = " (write_bytes writes bytes)" if isinstance(text, (bytes, bytearray, memoryview)) else ""
        raise ConfigError(f"{caller}: text must be a str, got {type(text).__name__}{hint}", source=path)
    return text.encode("utf-8")


def write_texts(texts: dict[str | os.PathLike, str]) -> list[Path]:
    """Write files that belong together (a report's .md, .csv and .html): every one is written in full first, then
    each renamed into place, so a failure while writing any of them (a full disk) replaces none; return the paths."""
    encoded = {path: _utf8(text, path, "write_texts") for path, text in texts.items()}  # all checked before any is written
    with paths_together(encoded) as aside:
        for path, data in encoded.items():
            _write_synced(aside[Path(path)], data)
    return [Path(p) for p in texts]


@contextlib.contextmanager
def paths_together(paths: Iterable[str | os.PathLike]) -> Iterator[dict[Path, Path]]:
    """Temporary paths (``{final: temporary}``) for outputs that belong together: the block writes each to its
    temporary path, and every one is renamed into place only after the block ended, so a failure or an interrupt in it
    replaces none (an evaluation's JSON was replaced and its figure, failing, kept the earlier run's); an interrupt
    during the renames takes effect after the last. Streams (a FIFO, /dev/stdout) are written into after the renames,
    interruptible: one waits for a reader, and a SIGTERM held off meanwhile never took effect."""
    paths = [Path(p) for p in paths]
    streams = {p for p in paths if _is_stream(p)}
    with contextlib.ExitStack() as stream_stack, contextlib.ExitStack() as file_stack:
        aside = {p: (stream_stack if p in streams else file_stack).enter_context(atomic_path(p)) for p in paths}
        try:
            yield aside
        except OutputError as err:  # named by its final path, not the temporary one it was written to
            final = {tmp.resolve(): path for path, tmp in aside.items()}.get(Path(err.source or "").resolve())
            if final is None:
                raise
            raise OutputError(err.reason, source=final, location=err.location) from err
        with interrupts_deferred():  # renamed in one after the other: all of them, never the first few
            file_stack.close()


def _write_synced(path: Path, data: bytes) -> None:
    with open(path, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())


def figure_format(fig, path: str | os.PathLike) -> str:
    """The format ``path``'s suffix names (PNG without one); an unknown suffix is an OutputError listing the known."""
    fmt = Path(path).suffix.lstrip(".").lower() or "png"
    if fig is None:
        from matplotlib.backend_bases import FigureCanvasBase

        known = FigureCanvasBase.get_supported_filetypes()
    else:
        known = fig.canvas.get_supported_filetypes()
    missing = _missing_program(fmt)
    if missing:
        raise OutputError(f"cannot write the plot: the .{fmt} format needs {missing!r} (matplotlib's "
                          "rcParams['pgf.texsystem']), which is not installed; use .pdf or .svg", source=path)
    if fmt not in known:
        usable = sorted(k for k in known if not _missing_program(k))
        raise OutputError(f"unknown plot format {'.' + fmt!r}; use one of: {', '.join('.' + k for k in usable)}",
                          source=path)
    return fmt


def _missing_program(fmt: str) -> str:
    """The program a plot format's backend runs that is not installed ("" when none is missing): .pgf runs
    rcParams['pgf.texsystem'] (xelatex, lualatex or pdflatex), whose absence was a traceback after all the work."""
    if fmt != "pgf":
        return ""
    program = _texsystem()
    return "" if shutil.which(program) else program


def save_figure(fig, path: str | os.PathLike, *, dpi: float | None = None) -> Path:
    """Save a matplotlib figure atomically, in the format its suffix names (PNG when there is none)."""
    path = Path(path)
    fmt = figure_format(fig, path)
    if fmt == "pgf":  # its TeX may start and fail (a broken installation, a missing package)
        from matplotlib.backends.backend_pgf import LatexError
    else:
        LatexError = ()  # noqa: N806 (nothing to catch)
    with atomic_path(path) as tmp:
        try:
            if fmt == "svgz":  # gzip names what it holds: matplotlib's named the hidden temporary file
                _save_svgz(fig, tmp, f"{path.stem}.svg", dpi)
            else:
                fig.savefig(tmp, format=fmt, dpi=dpi)
        except (ValueError, RuntimeError) as err:  # matplotlib's own refusal of a format or size; a backend's
            # program that fails to start (pgf's TeX, found by the check but not runnable) raises RuntimeError
            raise OutputError(f"cannot write the plot: {' '.join(str(err).split())}", source=path) from err
        except LatexError as err:
            raise OutputError(f"cannot write the plot: LaTeX errored: {_tex_complaint(err)}", source=path) from err
        except BrokenPipeError as err:
            if fmt != "pgf":
                raise
            # (a TeX that fails at once may exit before matplotlib has written its preamble: the same failure, timed
            # otherwise, read "cannot write: Broken pipe" as if the plot file were at fault)
            raise OutputError("cannot write the plot: LaTeX errored: the TeX program "
                              f"({_texsystem()}) exited before reading the figure", source=path) from err
    return path


def _save_svgz(fig, tmp: Path, inner_name: str, dpi: float | None) -> None:
    """The figure as gzipped SVG whose header names ``inner_name`` (what ``gunzip -N`` restores)."""
    import gzip
    import io

    svg = io.BytesIO()
    fig.savefig(svg, format="svg", dpi=dpi)
    with open(tmp, "wb") as raw, gzip.GzipFile(filename=inner_name, mode="wb", fileobj=raw, mtime=0) as packed:
        packed.write(svg.getvalue())


def _texsystem() -> str:
    """The TeX program matplotlib's .pgf backend runs (rcParams['pgf.texsystem'])."""
    import matplotlib

    return str(matplotlib.rcParams["pgf.texsystem"])


def _tex_complaint(err: Exception) -> str:
    """The line of a LatexError's TeX output that says what went wrong (TeX marks it with "!"), else its last line:
    the error itself quotes the whole preamble."""
    import matplotlib

    lines = [line.strip() for line in str(getattr(err, "latex_output", "")).splitlines() if line.strip()]
    marked = [line for line in lines if line.startswith("!")]
    said = marked[0] if marked else lines[-1] if lines else "no output"
    return f"{said} ({matplotlib.rcParams['pgf.texsystem']}, rcParams['pgf.texsystem']); use .pdf or .svg"


LINK_LOOP = "a loop of symbolic links (a link that leads back to itself)"


def resolved_path(path: str | os.PathLike, output: bool) -> Path:
    """``path`` with its links followed; one that cannot be (a loop of symbolic links, ``ln -s loop loop``: a
    RuntimeError from ``Path.resolve``) is a DataError for an input, an OutputError for an output, naming it."""
    try:
        return Path(path).resolve()
    except (RuntimeError, OSError) as err:
        reason = LINK_LOOP if isinstance(err, RuntimeError) else (err.strerror or type(err).__name__).lower()
        if output:
            raise OutputError(f"cannot write: {reason}", source=path) from None
        raise DataError(f"cannot read it: {reason}", source=path) from None


def missing_reason(path: str | os.PathLike, not_found: str = "not found") -> str:
    """Why an input ``path`` that does not exist is missing: a loop of symbolic links, a link to a missing file, or
    ``not_found`` (``Path.exists()`` is False for all three: a loop of links read "not found")."""
    try:
        os.stat(path)
    except OSError as err:
        if err.errno == errno.ELOOP:
            return f"cannot read it: {LINK_LOOP}"
        if err.errno == errno.ENOENT and os.path.islink(path):
            return f"a symbolic link to a missing file (-> {os.readlink(path)})"
    return not_found


def stream_reason(path: str | os.PathLike) -> str | None:
    """Why an input ``path`` that is a pipe or a device is refused where a file is read (its size or a second pass is
    needed), or None for anything else: "not a regular file" of ``<(...)``'s /dev/fd/63 did not say what to do."""
    import stat

    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    if stat.S_ISFIFO(mode):
        return "a pipe (e.g. <(...)): save it to a file first"
    if stat.S_ISCHR(mode):
        return "a device, not a file: save what it gives to a file first"
    return None


def check_target(path: str | os.PathLike | None, kind: str = "file", files: Iterable[str] = (),
                 replaces: Iterable[str] = ()) -> None:
    """Refuse an output path before any work is done: ``kind`` is ``"file"``, ``"figure"`` (a known plot suffix
    too) or ``"folder"``. Checks what is in the way and whether the nearest existing folder is writable; ``files``: the
    names a run writes into (or replaces in) the folder, none of which may be a folder (one was found after the run);
    ``replaces``: :func:`run_folder`'s, a folder that holds files of these names but never held a run is refused (a
    user's own config.yaml and metrics.json were replaced)."""
    if path is None:
        return
    path = Path(path)
    try:
        _check_target(path, kind)
        for name in files if kind == "folder" else ():
            if (path / name).is_dir():
                raise OutputError("cannot write: is a folder (a file name is needed here)", source=path / name)
        own = sorted(n for n in set(replaces) if os.path.lexists(path / n)) if path.is_dir() and not _holds_a_run(path) else []
        if own:
            # (a run a SIGKILL cut off before its config.yaml moved in looks the same: the message covers both)
            raise OutputError(f"holds files named like a run's ({', '.join(own)}) but no config.yaml written by lidarkit (the "
                              "user's own, or a run cut off before it was complete): a run would replace them; remove them or "
                              "give a new or empty folder", source=path)
    except OSError as err:  # pathlib re-raises what a stat of the path itself meets (a name too long: ENAMETOOLONG)
        raise OutputError(f"cannot write: {(err.strerror or str(err)).lower()}", source=path) from None


def refuse_dangling_link(path: str | os.PathLike, what: str = "folder") -> None:
    """OutputError when ``path``, or a folder above it, is a symbolic link to something missing: an output is never
    created where such a link points (a folder export to ``dangle -> /nonexistent/x`` made /nonexistent/x and its
    parents), as bags are never written there; ``what``: the kind of output, for the message. A loop of links is
    said as one (``ln -s loop loop`` was called a link to a missing file)."""
    path = Path(path)
    link = next((p for p in (path, *path.parents) if p.is_symlink() and not p.exists()), None)
    if link is not None:
        kind = LINK_LOOP if missing_reason(link).endswith(LINK_LOOP) else "a symbolic link to a missing file"
        raise OutputError(f"{kind} is in the way (-> {os.readlink(link)}): remove it or name another "
                          f"{what if link == path else 'folder'}", source=link)


def _longest_name(path: Path) -> tuple[int, int]:
    """Bytes of the longest name in ``path`` and the most the file system takes (NAME_MAX of the nearest existing
    folder, 255 where it cannot tell): a name too long for the disk failed only when the file was written, after the work."""
    longest = max((len(os.fsencode(part)) for part in path.parts), default=0)
    limit = _NAME_MAX
    for folder in path.absolute().parents:
        try:
            if folder.is_dir():
                limit = os.pathconf(folder, "PC_NAME_MAX")
                break
        except (OSError, ValueError):
            continue
    return longest, limit


def _check_target(path: Path, kind: str) -> None:
    longest, limit = _longest_name(path)
    if longest > limit:
        raise OutputError(f"cannot write: file name too long (a name of {longest} bytes; the file system takes at most {limit})",
                          source=path)
    if kind == "folder":
        if path.exists() and not path.is_dir():
            raise OutputError("cannot write the folder: a file is in the way (a folder is needed here)", source=path)
        refuse_dangling_link(path)  # (as run_folder does: refused before the work, not after it)
    else:
        if path.is_dir():
            raise OutputError("cannot write: is a folder (a file name is needed here)", source=path)
        if kind == "figure":
            figure_format(None, path)
        if _is_stream(path):  # written into, not beside (/dev/null, a FIFO): its own permission counts
            if not os.access(path, os.W_OK):
                raise OutputError("cannot write: permission denied", source=path)
            return
    candidates = (path.absolute(), *path.absolute().parents) if kind == "folder" else path.absolute().parents
    parent = next((p for p in candidates if p.exists()), None)
    if parent is not None and not parent.is_dir():
        raise OutputError("cannot create the folder: a file is in the way (a folder is needed here)", source=parent)
    if parent is not None and not os.access(parent, os.W_OK | os.X_OK):
        # access() reports a read-only file system even for root
        try:
            os.statvfs(parent)
            readonly = bool(os.statvfs(parent).f_flag & os.ST_RDONLY)
        except OSError:
            readonly = False
        raise OutputError(f"cannot write: {'read-only file system' if readonly else 'permission denied'}", source=path)
    if parent is not None:
        # access() passes where creating still fails (/sys, /proc, some network mounts): create what the writers
        # create first, a hidden folder beside the target, and remove it
        try:
            os.rmdir(tempfile.mkdtemp(prefix=".lidarkit-check-", dir=parent))
        except OSError as err:
            raise OutputError(f"cannot write: {(err.strerror or str(err)).lower()}", source=path) from None


@contextlib.contextmanager
def run_folder(path: str | os.PathLike, replaces: Iterable[str] = (), exclusive: bool = False) -> Iterator[Path]:
    """Yield a temporary folder to write a run into; on success it becomes ``path``, on failure it is removed.

    A new ``path`` appears in one rename, complete. An existing folder keeps its other files: the run's files are
    moved into it one rename each, only after all were written. Errors name ``path``, not the temporary folder.
    ``replaces``: the names a run of this kind can write; those this run did not write are removed from an existing
    folder that held an earlier run (its ``config.yaml`` names a lidarkit version: its ground truth or plots are never
    read as this run's); a folder that held no run keeps every file (a user's own ``trajectory.png`` went).
    ``exclusive``: ``path`` must be missing or empty when the run is moved in (one rename, which the file system refuses
    onto a folder that holds files: two exports to one folder at once merged before). A ``path`` that is a symbolic link
    is written where it points when that folder exists; a link to a missing folder is refused (see
    :func:`refuse_dangling_link`).
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputError("cannot write the folder: a file is in the way (a folder is needed here)", source=path)
    refuse_dangling_link(path)  # (a link to a missing folder was followed, and the folder made with all its parents)
    named = path
    if path.is_symlink():  # written beside the folder it names (a rename onto the link itself fails)
        path = path.resolve()
    path = Path(os.path.abspath(path))  # ("." has itself as parent: its temporary folder was made inside it)
    # a writable folder in a parent this user cannot write to (a mount point): written inside it, moved file by file
    inside = path.is_dir() and not _writable(path.parent) and _writable(path)
    with partial_folder(path, "cannot create the folder", inside=inside) as tmp:
        os.chmod(tmp, 0o777 & ~_UMASK)
        try:
            yield tmp
        except OutputError as err:
            if err.source and err.source.startswith(str(tmp)):  # name the final path, not the temporary one
                raise OutputError(err.reason, source=named / os.path.relpath(err.source, tmp), location=err.location) from err
            raise
        written = {p.name for p in tmp.iterdir()}
        # one run at a time moves into a folder (waited for before the signals are held: a wait that can be stopped);
        # two at once left 22 files of one beside 2978 of the other, or each removed the other's files
        with _destination_held(path, inside), interrupts_deferred():  # moved in file by file: a folder cut off
            # half-way looked finished (what the folder holds now, not when this run began: a run that finished into
            # it meanwhile left its pose_covariance.txt beside this run's config.yaml)
            held_a_run = _holds_a_run(path)
            with output_errors(named, "cannot complete the folder"):
                _move_into_place(tmp, path, exclusive, named, inside)
            for name in sorted(set(replaces) - written) if held_a_run else ():
                with output_errors(named / name, "cannot remove an earlier run's file"):
                    (path / name).unlink(missing_ok=True)


@contextlib.contextmanager
def interrupts_deferred() -> Iterator[None]:
    """SIGINT / SIGTERM / SIGHUP received in the block take effect when it ends, through the handlers in force before it
    (the CLI's: one line, exit 130 / 143 / 129). Main thread only (elsewhere the block runs as it is): a SIGTERM while
    an export's files were moved into an existing folder left sim.yaml, poses.txt and 327 of its 1000 sweeps."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []
    previous = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    for s, handler in previous.items():
        if handler is not signal.SIG_IGN:
            signal.signal(s, lambda signum, _frame: received.append(signum))
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
        for signum in dict.fromkeys(received):
            signal.raise_signal(signum)


def _writable(folder: Path) -> bool:
    return os.access(folder, os.W_OK | os.X_OK)


def temporary_stem(name: str, extra: int) -> str:
    """``name`` as the stem of a temporary name ``extra`` bytes longer: as it is when that fits in a name, else cut, with a
    digest of the whole name so that long names sharing their start keep apart (a legal 250-byte --out failed
    only after the run, when its ``.<name>.partial-XXXXXXXX`` folder could not be made)."""
    encoded = os.fsencode(name)
    if len(encoded) + extra <= _NAME_MAX:
        return name
    import hashlib

    cut = encoded[: _NAME_MAX - extra - 9].decode("utf-8", errors="ignore")  # (a multi-byte character is not split)
    return f"{cut}~{hashlib.sha1(encoded).hexdigest()[:8]}"


def _partial_prefix(path: Path) -> str:
    """``.<name>.partial-`` of ``path``'s temporary folders (the name cut to fit, see :func:`temporary_stem`)."""
    return f".{temporary_stem(path.name, 1 + len(PARTIAL_MARK) + _RANDOM_CHARS)}{PARTIAL_MARK}"


@contextlib.contextmanager
def partial_folder(path: str | os.PathLike, reason: str = "cannot write", inside: bool = False) -> Iterator[Path]:
    """A temporary folder beside ``path`` (``.<name>.partial-XXXX``; in it with ``inside``) to write ``path`` in,
    removed at the end (when it was not renamed into place). It is held (an advisory lock) while this process writes,
    so that another output's clean-up of killed runs' folders never takes it for one (an export writing for over an
    hour lost its folder to a second export and then reported success with half its sweeps)."""
    path = Path(path)
    home = path if inside else path.parent
    ensure_dir(home)
    with output_errors(path, reason):
        tmp = Path(tempfile.mkdtemp(prefix=_partial_prefix(path), dir=home))
    held = _hold(tmp)
    try:
        remove_stale_partials(path, home=home)
        yield tmp
    finally:
        try:
            with interrupts_deferred():  # (a SIGTERM in it left the folder behind)
                shutil.rmtree(tmp, ignore_errors=True)
        finally:
            if held is not None:
                os.close(held)


def _holds_a_run(path: Path) -> bool:
    """Whether ``path`` holds a lidarkit run (a ``config.yaml`` that names the lidarkit version that wrote it)."""
    try:
        return "lidarkit_version" in (path / "config.yaml").read_text(encoding="utf-8", errors="replace")[:1_000_000]
    except OSError:
        return False


@contextlib.contextmanager
def export_folder(path: str | os.PathLike, what: str) -> Iterator[Path]:
    """:func:`run_folder` for an export whose files must never mix with another export's (``what``: its items, for
    the message): a folder that already holds files is refused."""
    path = Path(path)
    if path.is_dir() and any(path.iterdir()):
        raise OutputError(f"the folder already holds files: an export never mixes its {what} with another's (remove it "
                          "or choose a new folder)", source=path)
    with run_folder(path, exclusive=True) as tmp:
        yield tmp


def _move_into_place(tmp: Path, path: Path, exclusive: bool = False, named: Path | None = None, inside: bool = False) -> None:
    """``tmp`` becomes ``path`` (``named``: the path as the user gave it, for messages); ``inside``: ``tmp`` is in
    ``path``, its files are moved up one rename each."""
    named = path if named is None else named
    filled = OutputError("the folder filled while this export was written (another export to it?): its files are kept, "
                         "this export is not written", source=named)
    if inside:
        if exclusive and any(p != tmp for p in path.iterdir()):
            raise filled
    elif path.is_dir():  # an existing folder is filled, never renamed over: it may be a shell's working folder (-o . was
        # "filled while written"; -o $PWD left the shell in a deleted folder)
        if exclusive and any(path.iterdir()):
            raise filled
    else:
        try:
            os.rename(tmp, path)  # a missing ``path``: one rename
            return
        except OSError as err:
            if err.errno not in (errno.EEXIST, errno.ENOTEMPTY, errno.EISDIR, errno.ENOTDIR, errno.EBUSY):
                raise
            if exclusive:
                raise filled from None
    finishing = [tmp / name for name in _FINISHING]  # in last, the earlier ones out first: a folder cut off lacks them
    moves = [(src, path / src.relative_to(tmp)) for src in sorted(tmp.rglob("*"), key=lambda p: (p in finishing, p))]
    # everything in the way is found before the first file moves: a folder where a file goes (or a file where a folder
    # goes) found half-way left the folder half the earlier run's, half this one's
    for src, dst in moves:
        if not src.is_dir() and dst.is_dir():
            raise OutputError("cannot write: is a folder (a file name is needed here)", source=named / src.relative_to(tmp))
        if src.is_dir() and dst.exists() and not dst.is_dir():
            raise OutputError("cannot create the folder: a file is in the way (a folder is needed here)",
                              source=named / src.relative_to(tmp))
    # each file replaced is kept aside until the last is in: one that cannot be replaced (owned by another user in a
    # shared folder, immutable) puts the earlier ones back (the folder was left half the earlier run's, half this one's)
    aside = tmp / ".replaced"
    done: list[tuple[Path, Path, Path | None]] = []
    withdrawn: list[tuple[Path, Path]] = []  # (an earlier run's finishing file, where it is kept)
    src = tmp
    try:
        # the earlier run's finishing files that this run replaces go aside before any file moves in: a folder a SIGKILL
        # cut off half-way held the earlier config.yaml beside the new metrics.json and was compared as a finished run
        for src in (p for p in finishing if p.exists()):
            dst = path / src.name
            if dst.exists() or dst.is_symlink():
                aside.mkdir(exist_ok=True)
                kept = aside / f"finishing-{len(withdrawn)}"
                os.rename(dst, kept)
                withdrawn.append((dst, kept))
        for src, dst in moves:
            if src.is_dir():
                ensure_dir(dst)
                continue
            ensure_dir(dst.parent)
            kept = None
            if dst.exists() or dst.is_symlink():
                aside.mkdir(exist_ok=True)
                kept = aside / str(len(done))
                os.rename(dst, kept)
            try:
                os.replace(src, dst)
            except OSError:
                if kept is not None:
                    os.rename(kept, dst)
                raise
            done.append((src, dst, kept))
    except OSError as err:
        for moved, into, kept in reversed(done):
            with contextlib.suppress(OSError):
                os.replace(into, moved)  # (this run's file back where it was written)
                if kept is not None:
                    os.rename(kept, into)
        for into, kept in reversed(withdrawn):
            with contextlib.suppress(OSError):
                os.rename(kept, into)
        raise OutputError(f"cannot replace it ({_reason(err)}): the folder is left as it was",
                          source=named / src.relative_to(tmp)) from err


LOCK_SUFFIX = ".lock"  # ``.<name>.lock`` beside a folder while a run moves into it


@contextlib.contextmanager
def _destination_held(path: Path, inside: bool) -> Iterator[None]:
    """Hold ``path`` against other lidarkit processes moving a run into it (waiting for one that is): an advisory lock
    on ``.<name>.lock`` beside it, removed after; on ``path`` itself where its parent cannot be written (``inside``).
    Without locks (not POSIX), or where neither can be opened, the block runs as it is."""
    if inside:
        held = _hold(path)
        try:
            yield
        finally:
            if held is not None:
                os.close(held)
        return
    lock = path.parent / f".{temporary_stem(path.name, 1 + len(LOCK_SUFFIX))}{LOCK_SUFFIX}"
    held = _hold_lock_file(lock)
    try:
        yield
    finally:
        if held is not None:
            with contextlib.suppress(OSError):
                os.unlink(lock)  # (while still held: a process waiting on it sees it gone and takes a new one)
            os.close(held)


def _hold_lock_file(lock: Path) -> int | None:
    """An open descriptor of ``lock`` (created if missing) holding an exclusive advisory lock on it, waiting for any
    other holder; None without locks or where it cannot be created. A lock file its holder removed meanwhile is
    opened anew (whoever waited on the removed one would otherwise hold a lock nobody else sees)."""
    if fcntl is None:
        return None
    while True:
        try:
            fd = os.open(lock, os.O_RDONLY | os.O_CREAT, 0o666 & ~_UMASK)
        except OSError:
            return None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            held, named = os.fstat(fd), os.stat(lock)
            if (held.st_dev, held.st_ino) == (named.st_dev, named.st_ino):
                return fd
        except FileNotFoundError:
            pass
        except BaseException:
            os.close(fd)
            raise
        os.close(fd)


def _hold(folder: Path, wait: bool = True) -> int | None:
    """An open descriptor of ``folder`` holding an exclusive advisory lock on it (released when closed, or when the
    process ends however it ends); None without locks (not POSIX), or when another process holds it (``wait=False``)."""
    if fcntl is None:
        return None
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX if wait else fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        return None
    return fd


def remove_stale_partials(path: str | os.PathLike, older_than_s: float = 3600.0, home: str | os.PathLike | None = None) -> int:
    """Remove temporary run folders of ``path`` a killed run left behind in ``home`` (default: beside ``path``): older
    than ``older_than_s`` and held by no running process (a folder's own time stamp does not change while files are
    written inside it)."""
    path = Path(path)
    removed = 0
    with contextlib.suppress(OSError):
        for stale in Path(path.parent if home is None else home).glob(f"{_partial_prefix(path)}*"):
            if not (stale.is_dir() and time.time() - stale.stat().st_mtime > older_than_s):
                continue
            held = _hold(stale, wait=False)
            if held is None and fcntl is not None:
                continue  # a running output's folder (or one this process cannot open: left alone)
            try:
                shutil.rmtree(stale, ignore_errors=True)
                removed += 1
            finally:
                if held is not None:
                    os.close(held)
    return removed
