"""`master examples [DIR]`: copy the project's scenes out of the package, so that an installed
master has scenes to run.

A scene is a folder of models/ with a SystemStructure.ssd; it runs with that file, its parameter
files (.ssv) and its README (SCENE_FILES). Its FMUs are named `project:NAME` and built on demand
from the sources in the package, so a copied scene runs from any folder. setup.py puts the same
files into the wheel (master/models), reading scene_files() from this module by its path: keep
this module free of imports from the package.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
SCENE_FILE = "SystemStructure.ssd"
SCENE_FILES = (SCENE_FILE, "*.ssv", "README.md")
# the scenes: shipped inside an installed package (setup.py), else the checkout's models/
SCENES_DIR = PACKAGE_DIR / "models" if (PACKAGE_DIR / "models").is_dir() else PACKAGE_DIR.parent / "models"
DEFAULT_DIR = "master-examples"


def scene_files(models: Path = SCENES_DIR) -> dict[str, list[Path]]:
    """Each scene folder's name in `models` -> the files it runs with, both sorted."""
    scenes = sorted(d for d in models.iterdir() if (d / SCENE_FILE).is_file())
    return {d.name: sorted({p for pattern in SCENE_FILES for p in d.glob(pattern)}) for d in scenes}


def copy_examples(dest: Path, force: bool = False) -> dict[Path, list[str]]:
    """Copy every scene into dest/<scene>/; returns each folder written -> its file names.

    Without `force`, a file that exists already raises FileExistsError and nothing is written."""
    if dest.exists() and not dest.is_dir():
        raise NotADirectoryError(f"{dest}: not a folder")
    copies = [(src, dest / name / src.name) for name, files in scene_files().items() for src in files]
    existing = [target for _, target in copies if target.exists()]
    if existing and not force:
        more = f" (and {len(existing) - 1} more)" if len(existing) > 1 else ""
        raise FileExistsError(f"{existing[0]}: exists{more}; --force overwrites the examples' files")
    written: dict[Path, list[str]] = {}
    for src, target in copies:
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, target)  # not copy2: a read-only installed file gives a writable copy
        written.setdefault(target.parent, []).append(target.name)
    return written


def main(dest: str = DEFAULT_DIR, force: bool = False) -> int:
    """Copy the scenes, print each folder and the command that runs it; returns the exit status."""
    try:
        written = copy_examples(Path(dest), force)
    except OSError as e:  # a file that exists, a DEST that is a file, no permission
        print(f"error: {e.filename}: {e.strerror}" if e.filename else f"error: {e}", file=sys.stderr)
        return 1
    for folder, names in written.items():
        print(f"{folder}: {', '.join(names)}")
        print(f"  master run {folder / SCENE_FILE}")
    return 0
