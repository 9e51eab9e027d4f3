"""Zip archives (.fmu, .ssp): which members may be extracted, and whether the data reads back."""

from __future__ import annotations

import stat
import zipfile
import zlib
from pathlib import Path, PurePosixPath

METHODS = {zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED, zipfile.ZIP_BZIP2, zipfile.ZIP_LZMA}
DAMAGED = (OSError, zipfile.BadZipFile, zlib.error, EOFError, RuntimeError, NotImplementedError)


def damaged(path: Path) -> str | None:
    """Why the zip archive `path` (.ssp or .fmu) cannot be unpacked safely, or None: an unsafe
    member, or data that does not read back (every member is read and its CRC checked)."""
    try:
        with zipfile.ZipFile(path) as zf:
            for info in zf.infolist():
                reason = unsafe(info)
                if reason:
                    return f'member "{info.filename}": {reason}'
            bad = zf.testzip()
    except DAMAGED as err:
        return f"damaged archive: {err}"
    return f'member "{bad}": damaged data (CRC)' if bad else None


def unsafe(info: zipfile.ZipInfo) -> str | None:
    """Why a member may not be extracted, or None if it is safe."""
    name = info.filename
    if "\\" in name:
        return "backslash in member path"
    if name.startswith("/") or PurePosixPath(name).is_absolute() or (len(name) > 1 and name[1] == ":"):
        return "absolute member path"
    if ".." in PurePosixPath(name).parts:
        return "member path escapes the archive ('..')"
    mode = info.external_attr >> 16
    if stat.S_ISLNK(mode):
        return "symbolic link member"
    if info.flag_bits & 0x1:
        return "encrypted member"
    if info.compress_type not in METHODS:
        return f"unknown compression method {info.compress_type}"
    return None
