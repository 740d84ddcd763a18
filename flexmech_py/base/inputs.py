"""Reading the files and folders a user names (a case file, a reference CSV, a folder of cases): one
clear line for each way a path can fail -- missing, a folder, a link that loops or leads nowhere, a
device or FIFO (never opened: reading one could block forever), unreadable, a name too long -- and
the text read as UTF-8 (a byte-order mark dropped)."""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from .errors import CaseError

__all__ = ["checked_file", "checked_folder", "read_text"]


def _stat(p: Path, field: str, what: str, hint: str) -> os.stat_result:
    try:
        return p.stat()
    except FileNotFoundError:
        if p.is_symlink():
            raise CaseError(field, f"{str(p)!r} is a symbolic link to {os.readlink(p)!r}, which does not exist; {hint}") \
                from None
        raise CaseError(field, f"{str(p)!r} does not exist; {hint}") from None
    except OSError as exc:
        why = {errno.ELOOP: "is a symbolic link that leads back to itself (a loop)",
               errno.ENAMETOOLONG: "is a path too long for the file system",
               errno.ENOTDIR: "goes through something that is a file, not a folder",
               errno.EACCES: "cannot be reached (permission denied on a folder of its path)"}
        raise CaseError(field, f"{str(p)!r} {why.get(exc.errno, f'cannot be used ({exc.strerror})')}; {hint}") from None


def checked_file(path, field: str, what: str, hint: str) -> Path:
    """``path`` when it is a regular file (or a link to one); CaseError naming ``field`` otherwise.
    ``what``: e.g. "case file"; ``hint``: the fix, e.g. "give the path of a .toml case file"."""
    p = Path(path)
    st = _stat(p, field, what, hint)
    if stat.S_ISDIR(st.st_mode):
        raise CaseError(field, f"{str(p)!r} is a folder, not a {what}; {hint}")
    if not stat.S_ISREG(st.st_mode):
        kind = "FIFO" if stat.S_ISFIFO(st.st_mode) else "socket" if stat.S_ISSOCK(st.st_mode) else "device"
        raise CaseError(field, f"{str(p)!r} is not a regular file (a {kind}); {hint}")
    return p


def checked_folder(path, field: str, what: str, hint: str) -> Path:
    """``path`` when it is a folder; CaseError naming ``field`` otherwise."""
    p = Path(path)
    st = _stat(p, field, what, hint)
    if not stat.S_ISDIR(st.st_mode):
        raise CaseError(field, f"{str(p)!r} is a file, not a folder of {what}; {hint}")
    return p


def read_text(path, field: str, what: str, hint: str) -> str:
    """The UTF-8 text of a user's file (a leading byte-order mark dropped); CaseError naming ``field``
    for a path that is not a readable regular file, or bytes that are not UTF-8 text (with the offset
    of the first bad byte)."""
    p = checked_file(path, field, what, hint)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise CaseError(field, f"{str(p)!r} cannot be read ({exc.strerror or exc}); {hint}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise CaseError(field, f"{p} is not a text {what} (byte {raw[exc.start]:#04x} at offset {exc.start} is not "
                               "UTF-8); give a UTF-8 text file") from None
    return text[1:] if text.startswith("\ufeff") else text
