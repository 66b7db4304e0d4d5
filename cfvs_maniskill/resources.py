"""Where the files a user can edit or add live: the bundled ones and the user's own.

Four kinds, each a folder: `tasks/` (task files), `sensors/` (sensor profiles), `assets/`
(hole objects: `assets/holes/` is the default library, beside the CAD parts and the
evaluation sets) and `agents/` (trained weights). The bundled ones ship inside the package
(`cfvs_maniskill/bundled/`, read with importlib.resources: in a checkout it links to the
repository's top-level folders, in a wheel it holds copies). The user's own go in one
folder, `$CFVS_HOME` (default `~/.cfvs_maniskill`), laid out the same way and searched
after the bundled files; a path on the command line works everywhere too.
"""

from __future__ import annotations

import os
import tempfile
from importlib import resources
from pathlib import Path
from typing import Literal

Kind = Literal["tasks", "sensors", "assets", "agents"]
KINDS: tuple[Kind, ...] = ("tasks", "sensors", "assets", "agents")
HOME_ENV = "CFVS_HOME"
"""Environment variable naming the user folder (like ManiSkill's MS_ASSET_DIR)."""
CACHE_ENV = "CFVS_CACHE"
"""Environment variable naming the cache folder (derived URDFs, hole collision builds)."""


def cache_root() -> Path:
    """Where derived files go: `$CFVS_CACHE`, else `~/.cache/cfvs_maniskill` if it can be
    written, else a folder of this user's in the temporary directory (a read-only HOME). Only
    making an env writes there; importing the package writes nothing."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    home = Path.home() / ".cache" / "cfvs_maniskill"
    try:
        home.mkdir(parents=True, exist_ok=True)
        if os.access(home, os.W_OK):
            return home
    except OSError:
        pass
    return Path(tempfile.gettempdir()) / f"cfvs_maniskill-{os.getuid()}"


def bundled_root() -> Path:
    root = resources.files("cfvs_maniskill") / "bundled"
    if not isinstance(root, Path):  # a zipped install: SAPIEN and trimesh need real files
        raise RuntimeError(
            f"cfvs_maniskill's bundled files are not on the file system ({root!r}); "
            "install the package unzipped (pip install cfvs_maniskill)"
        )
    return root


def bundled(kind: Kind) -> Path:
    """The bundled folder of `kind`, e.g. bundled("tasks")."""
    return bundled_root() / kind


def user_root() -> Path:
    return Path(os.environ.get(HOME_ENV) or Path.home() / ".cfvs_maniskill").expanduser()


def user(kind: Kind) -> Path:
    """The user's folder of `kind` (it may not exist)."""
    return user_root() / kind


def search_dirs(kind: Kind, sub: str = "") -> list[Path]:
    """Bundled first, then the user's folder when it exists."""
    dirs = [bundled(kind) / sub, user(kind) / sub]
    return [d for i, d in enumerate(dirs) if i == 0 or d.is_dir()]


def find(kind: Kind, spec: str | Path, suffix: str = ".yaml", sub: str = "") -> Path | None:
    """A file or folder named by `spec`: an existing path as given, else `<spec><suffix>` in
    the bundled folder, else in the user's. None when none has it."""
    p = Path(spec).expanduser()
    if p.exists():
        return p
    for d in search_dirs(kind, sub):
        for candidate in (d / f"{spec}{suffix}", d / str(spec)):
            if candidate.exists():
                return candidate
    return None


def key(path: Path | str) -> str | None:
    """A bundled file's name as in the repository (`tasks/PegInsert6DoF.yaml`), the same in
    a checkout and in an installed wheel; None for a file outside the bundle."""
    p = Path(path).resolve()
    for kind in KINDS:
        try:
            return f"{kind}/{p.relative_to(bundled(kind).resolve()).as_posix()}"
        except ValueError:
            continue
    return None


def bundled_file(file_key: str) -> Path:
    """The inverse of `key`: `tasks/PegInsert6DoF.yaml` -> its path in the bundle."""
    return bundled_root() / file_key
