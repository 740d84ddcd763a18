"""File names made from a user's words: a case name, an output column, a link, a model, a reference.

Every file flexmech names after something a user wrote goes through :func:`safe_name`, and every
such file is placed with :func:`inside` (which checks it), so no name (``../../x``, ``/etc/x``, ``a/b``, a name of
100 000 characters, ``NUL``) can put a file outside the folder it belongs in.  A name that is
already safe (letters, digits, ``_ . - +``, at most NAME_MAX characters, not starting with a dot
or a dash) is kept as it is, so the files of ordinary names do not change.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

from .errors import FlexmechError

__all__ = ["safe_name", "inside", "NAME_MAX"]

#: characters of a safe name at most (file systems allow 255 bytes; room is left for prefixes and suffixes)
NAME_MAX = 120
_UNSAFE = re.compile(r"[^A-Za-z0-9_.+-]+")


def safe_name(text) -> str:
    """``text`` as one file-name component: kept when safe; otherwise every run of other characters
    becomes ``_``, leading dots and dashes go, the result is cut to NAME_MAX characters, and an
    8-digit hash of the original text is appended, so two different names stay two files."""
    text = str(text)
    clean = _UNSAFE.sub("_", text).lstrip(".-")
    if clean == text and 0 < len(text) <= NAME_MAX:
        return text
    digest = hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()[:8]
    return f"{clean[:NAME_MAX - 9] or 'name'}-{digest}"


def inside(folder, *names) -> Path:
    """``folder / name / ...``, each name one component of a file name (compose them from
    :func:`safe_name`, e.g. ``inside(out, f"compare_{safe_name(column)}.png")``); FlexmechError when a
    name would leave ``folder`` (a bug in the caller: this is the last line of defence)."""
    base = Path(folder)
    for n in names:
        n = str(n)
        if not n or n in (".", "..") or "/" in n or "\0" in n or len(n.encode("utf-8", "replace")) > 255:
            raise FlexmechError(f"{n[:80]!r} is not a file name inside {str(base)!r}")
    path = base.joinpath(*names)
    root = base.resolve()
    if root != path.resolve() and root not in path.resolve().parents:
        raise FlexmechError(f"the file name {str(path)[:200]!r} would leave the folder {str(base)[:200]!r}")
    return path
