"""Hole-object asset tools: `python -m cfvs_maniskill.assets check [DIR ...]`.

`check` validates every spec in `assets/holes/` and the given directories, cuts the hole for
each peg profile it hosts and decomposes it (filling the cache), and prints one table row per
file: name, split, body, hole profiles, collision parts, ok / error. Exit code 1 if any file
is invalid; one bad file never hides the others.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import tyro
from rich.console import Console
from rich.table import Table

from cfvs_maniskill.constants import DEFAULT_CLEARANCE, DEFAULT_HOLE_DEPTH
from cfvs_maniskill.objects.build import build_geometry
from cfvs_maniskill.objects.library import load_library
from cfvs_maniskill.objects.spec import HoleSpecError


@dataclass
class Check:
    """Validate hole-object specs and build their geometry."""

    dirs: Annotated[tuple[Path, ...], tyro.conf.Positional] = ()
    """Extra directories or files of hole-object YAML specs (assets/holes/ is always checked)."""
    clearance: float = DEFAULT_CLEARANCE
    """Hole minus peg width, metres."""
    depth: float = DEFAULT_HOLE_DEPTH
    """Hole depth, metres."""
    no_default: bool = False
    """Skip the shipped assets/holes/ directory."""


def check(args: Annotated[Check, tyro.conf.OmitArgPrefixes]) -> int:
    console = Console(width=160)
    try:
        lib = load_library(args.dirs, include_default=not args.no_default)
    except FileNotFoundError as e:
        console.print(f"[red]error:[/red] {e}")
        return 2
    table = Table(title="hole objects")
    for col in ("name", "split", "body", "hole profiles", "collision parts", "status"):
        table.add_column(col, overflow="fold")
    bad = 0
    for spec in sorted(lib.specs.values(), key=lambda s: s.name):
        parts, status = [], "[green]ok[/green]"
        try:
            for profile in spec.hole:
                g = build_geometry(spec, profile, args.clearance, args.depth)
                parts.append(f"{profile} {len(g.collision_parts)}")
        except HoleSpecError as e:
            status, bad = f"[red]error[/red] {e}", bad + 1
        table.add_row(
            spec.name,
            spec.split,
            spec.describe_body(),
            ", ".join(spec.hole),
            ", ".join(parts),
            status,
        )
    for e in lib.errors:
        bad += 1
        table.add_row(Path(e.file).stem, "-", "-", "-", "-", f"[red]error[/red] {e}")
    console.print(table)
    console.print(f"{len(lib.specs) + len(lib.errors) - bad} ok, {bad} with errors")
    return 1 if bad else 0


def main() -> None:
    cmd = tyro.extras.subcommand_cli_from_dict({"check": check})
    raise SystemExit(cmd)


if __name__ == "__main__":
    main()
