"""The one shape of error a bad input file gets: which file, which field, what was expected."""

from __future__ import annotations

from pathlib import Path


class FileFieldError(ValueError):
    """A file that cannot be used. `str()` names file, field and expectation."""

    def __init__(self, file: Path | str, field: str, message: str):
        self.file = str(file)
        self.field = field
        self.message = message
        super().__init__(f"{self.file}: field '{field}': {message}")

    def __reduce__(self):
        # Raised in an eval worker process, it must survive the trip back to the parent
        # intact (the default pickling calls __init__ with the message alone and fails).
        return type(self), (self.file, self.field, self.message)
