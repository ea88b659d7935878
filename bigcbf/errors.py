"""User-facing errors: bad input is reported with the file and the field, never as a traceback."""
from __future__ import annotations


class UserError(Exception):
    """A mistake in something the user gave us (a file, a parameter, a CLI argument).

    The CLI prints ``str(err)`` and exits with status 2; no traceback.
    """

    def __init__(self, message: str, *, file: str | None = None, field: str | None = None):
        self.file = None if file is None else str(file)
        self.field = field
        self.message = message
        where = []
        if self.file:
            where.append(self.file)
        if field:
            where.append(f"field '{field}'")
        super().__init__(f"{': '.join(where)}: {message}" if where else message)


class FieldError(ValueError):
    """A dataclass's own validation (``__post_init__``) naming the field at fault; ``params.toml_io.from_dict``
    turns it into a UserError naming the file and the field (joined to the table's path)."""

    def __init__(self, field: str, message: str):
        self.field = field
        super().__init__(message)
