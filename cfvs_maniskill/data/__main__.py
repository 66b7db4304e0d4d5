"""`python -m cfvs_maniskill.data collect|show`: make CFVS datasets and look at them."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import tyro

from cfvs_maniskill.data.collect import CollectArgs


@dataclass
class ShowArgs:
    """Draw one sample (cloud, keypoints, confidence map or action) to a PNG."""

    file: Annotated[Path, tyro.conf.Positional]
    """Dataset file (HDF5) written by `collect`."""
    index: int = 0
    """Sample to draw."""
    out: Path = Path("sample.png")
    """PNG to write."""


def main(argv: list[str] | None = None) -> int:
    args = tyro.extras.subcommand_cli_from_dict(
        {"collect": CollectArgs, "show": ShowArgs},
        args=argv,
        description="CFVS datasets: `collect` coarse/fine HDF5 files, `show` one sample.",
    )
    from cfvs_maniskill.data.store import DatasetError
    from cfvs_maniskill.envs.lookup import UnknownTaskError
    from cfvs_maniskill.envs.task_config import TaskConfigError
    from cfvs_maniskill.objects.library import SelectionError
    from cfvs_maniskill.objects.spec import HoleSpecError

    try:
        if isinstance(args, ShowArgs):
            from cfvs_maniskill.data.show import show

            print(show(args.file, args.index, args.out))
        else:
            from cfvs_maniskill.data.collect import collect
            from cfvs_maniskill.sensing.profile import load_profile

            try:
                load_profile(args.sensor)
            except ValueError as e:
                print(f"error: {e}", file=sys.stderr)
                return 2
            collect(args)
    except (DatasetError, TaskConfigError, UnknownTaskError, SelectionError, HoleSpecError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted: the samples collected so far are kept; run again to resume")
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
