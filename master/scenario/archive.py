"""Safe extraction of .ssp archives into a per-archive cache folder."""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
import zipfile
from pathlib import Path

from master.archives import DAMAGED, unsafe

from .problems import Problems

SSD_NAME = "SystemStructure.ssd"
MAX_UNPACKED_BYTES = 512 << 20  # 512 MiB: a larger archive is more likely a zip bomb than a scene
CACHE_BYTES = 1 << 30  # the unpacked archives kept, least recently used evicted beyond this
MAX_RATIO = 200  # unpacked / packed size beyond which (and beyond 64 MiB) an archive is a zip bomb


def cache_root() -> Path:
    """Where archives are unpacked: $MULTIRATE_MASTER_CACHE or <tmp>/multirate-master-ssp."""
    env = os.environ.get("MULTIRATE_MASTER_CACHE")
    return Path(env) if env else Path(tempfile.gettempdir()) / "multirate-master-ssp"


def extract(archive: Path, shown: str, problems: Problems) -> Path | None:
    """Unpack `archive` (checked member by member) and return the folder holding its
    SystemStructure.ssd, or None after adding problems.  Nothing is written if any
    member is unsafe.  The folder is keyed by the archive's SHA-256, so it is reused."""
    try:
        digest = hashlib.sha256(archive.read_bytes()).hexdigest()[:20]
        zf = zipfile.ZipFile(archive)
    except (OSError, zipfile.BadZipFile) as err:
        problems.add(shown, None, "archive", f"not a readable .ssp (zip) archive: {err}")
        return None
    with zf:
        members = zf.infolist()
        bad = False
        for info in members:
            reason = unsafe(info)
            if reason:
                problems.add(shown, None, f'member "{info.filename}"', f"rejected: {reason}")
                bad = True
        if bad:
            return None
        unpacked = sum(i.file_size for i in members)
        if unpacked > MAX_UNPACKED_BYTES:
            problems.add(shown, None, "archive", f"unpacks to more than {MAX_UNPACKED_BYTES} bytes")
            return None
        packed = archive.stat().st_size
        if unpacked > 64 << 20 and unpacked > MAX_RATIO * packed:
            problems.add(
                shown, None, "archive", f"unpacks {packed} bytes into {unpacked}: more than {MAX_RATIO} times"
            )
            return None
        if SSD_NAME not in zf.namelist():
            problems.add(shown, None, "archive", f"has no {SSD_NAME} at its root")
            return None
        target = cache_root() / digest
        if (target / SSD_NAME).is_file():
            os.utime(target)  # recently used: evicted last
            return target
        target.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=".unpack-", dir=target.parent))
        try:
            for info in members:
                zf.extract(info, staging)
            try:
                staging.rename(target)  # atomic: concurrent loaders never see half an archive
            except OSError:
                if not (target / SSD_NAME).is_file():
                    raise
        except DAMAGED as err:
            problems.add(shown, None, "archive", f"cannot unpack (damaged archive?): {err}")
            return None
        finally:
            shutil.rmtree(staging, ignore_errors=True)
        _evict(target)
        return target


def _evict(keep: Path) -> None:
    """Remove the least recently used unpacked archives until the cache holds CACHE_BYTES at most."""
    entries = []
    for d in keep.parent.iterdir():
        if d.is_dir() and not d.name.startswith(".") and d != keep:
            size = sum(f.stat().st_size for f in d.rglob("*") if f.is_file())
            entries.append((d.stat().st_mtime, size, d))
    total = sum(size for _, size, _ in entries) + sum(
        f.stat().st_size for f in keep.rglob("*") if f.is_file()
    )
    for _, size, d in sorted(entries):
        if total <= CACHE_BYTES:
            break
        shutil.rmtree(d, ignore_errors=True)
        total -= size
