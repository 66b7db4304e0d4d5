"""Find hole-object specs in asset directories and select them by name or split."""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from cfvs_maniskill import resources
from cfvs_maniskill.objects.spec import SPLITS, HoleSpec, HoleSpecError, load_spec


class SelectionError(ValueError):
    """An --objects entry that matches nothing; the message lists the valid names."""


@dataclass
class Library:
    """Valid specs by name, plus the files that failed validation (never fatal for the rest)."""

    specs: dict[str, HoleSpec] = field(default_factory=dict)
    errors: list[HoleSpecError] = field(default_factory=list)

    def select(self, selectors: Sequence[str] | None, profile: str | None = None) -> list[HoleSpec]:
        """Specs matching any selector (a name or a split: train/test/all), in name order.

        `profile` keeps only objects that can host that peg profile.
        """
        pool = {n: s for n, s in self.specs.items() if profile is None or profile in s.hole}
        chosen: dict[str, HoleSpec] = {}
        for sel in selectors or ["all"]:
            if sel == "all":
                chosen.update(pool)
            elif sel in SPLITS:
                chosen.update({n: s for n, s in pool.items() if s.split == sel})
            elif sel in pool:
                chosen[sel] = pool[sel]
            else:
                why = ""
                if sel in self.specs:
                    why = f" (it cannot host a {profile} peg)"
                bad = [e for e in self.errors if Path(e.file).stem == sel]
                if bad:
                    why = f" (its file is invalid: {bad[0]})"
                valid = ", ".join(["all", *SPLITS, *sorted(pool)])
                raise SelectionError(f"unknown object '{sel}'{why}; valid: {valid}")
        if not chosen:
            raise SelectionError(
                f"no object matches {list(selectors or [])} for a {profile} peg; "
                f"valid: {', '.join(sorted(pool))}"
            )
        return [chosen[n] for n in sorted(chosen)]


def spec_files(directories: Iterable[Path]) -> list[Path]:
    files: list[Path] = []
    for d in directories:
        d = Path(d)
        if d.is_file():
            files.append(d)
        elif d.is_dir():
            files += sorted(p for p in d.iterdir() if p.suffix in (".yaml", ".yml"))
        else:
            raise FileNotFoundError(f"asset directory not found: {d}")
    return files


def load_library(extra_dirs: Iterable[Path | str] = (), include_default: bool = True) -> Library:
    """Load every spec in the default library `assets/holes/` (bundled, then the user
    folder's, resources.py) and in `extra_dirs` (`--assets DIR`).

    A file that fails validation is recorded in `errors` and skipped; a name defined twice
    is an error on the later file.
    """
    dirs = (resources.search_dirs("assets", "holes") if include_default else []) + [
        Path(d) for d in extra_dirs
    ]
    lib = Library()
    for f in spec_files(dirs):
        try:
            spec = load_spec(f)
        except HoleSpecError as e:
            lib.errors.append(e)
            continue
        if spec.name in lib.specs:
            first = lib.specs[spec.name].source
            error = HoleSpecError(f, "name", f"'{spec.name}' is already defined by {first}")
            lib.errors.append(error)
            # Said at once: asked for by name, the first file's object is the one used.
            warnings.warn(f"{error}; this file is not used: rename it", stacklevel=2)
            continue
        lib.specs[spec.name] = spec
    return lib
