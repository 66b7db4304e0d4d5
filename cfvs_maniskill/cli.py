"""What every command line does with bad input: one line naming what is wrong, exit code 2."""

from __future__ import annotations

import sys


def fail(message: str) -> None:
    """Print `error: message` to stderr and exit with code 2 (no traceback)."""
    print(f"error: {message}", file=sys.stderr)
    raise SystemExit(2)
