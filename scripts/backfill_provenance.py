"""Give every committed result record made before records carried provenance a
reconstructed one: `{"code": COMMIT, "reconstructed": "git"}`, COMMIT being the commit that
added its line (`git blame`). `report` fills in the files from git (report/trace.py).

    .venv/bin/python scripts/backfill_provenance.py results
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tqdm import tqdm

from cfvs_maniskill.constants import PROJECT_ROOT


def main(root: Path) -> None:
    for f in tqdm(sorted(root.rglob("*.jsonl")), desc="files"):
        rel = f.resolve().relative_to(PROJECT_ROOT).as_posix()
        blame = subprocess.run(
            ["git", "-C", str(PROJECT_ROOT), "blame", "-l", "-s", "--", rel],
            capture_output=True, text=True, check=True,
        ).stdout.splitlines()  # fmt: skip
        lines = f.read_text().splitlines()
        if len(blame) != len(lines):
            sys.exit(f"{f}: {len(lines)} lines, git blame gives {len(blame)}: commit it first")
        out = []
        for line, who in zip(lines, blame, strict=True):
            if line.strip():
                rec = json.loads(line)
                rec.setdefault("provenance", {"code": who[:12], "reconstructed": "git"})
                line = json.dumps(rec)
            out.append(line)
        f.write_text("\n".join(out) + "\n")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
