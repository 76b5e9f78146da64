"""Which code produced a result: the release number alone does not change between commits of a development checkout.

``code_version()`` is the release number with a digest of the package's own source files (``0.1.0+src.1a2b3c4d5e``):
a benchmark result is keyed by it, so a folder resumed after the code changed runs its jobs again instead of
keeping results the current code would not give, and every run folder records it.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path


@functools.lru_cache(maxsize=1)
def source_digest() -> str:
    """First 10 hex digits of SHA-256 over the package's ``.py`` files (relative path and content, in path order)."""
    root = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(b"\0")
        digest.update(path.read_bytes())
        digest.update(b"\0")
    return digest.hexdigest()[:10]


def code_version() -> str:
    """``RELEASE+src.DIGEST``: the release number and the digest of the source that is running."""
    from lidarkit import __version__

    return f"{__version__}+src.{source_digest()}"


__all__ = ["code_version", "source_digest"]
