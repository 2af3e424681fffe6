"""Errors named by what the runner should do with them.

- ConfigError: fail before any work starts (bad file, unknown key, bad value).
- FatalError: stop the whole run (broken install, simulator missing).
  - InputError: a file the stage cannot do without is malformed; names the file and field.
- EpisodeError: record the reason for this unit of work and go on.
- RetryableError: back off and try again (a VLM server's 429/503, a timeout).
"""

from __future__ import annotations

from pydantic import ValidationError


class RecoverError(Exception):
    """Base of all project errors."""


class ConfigError(RecoverError):
    """Configuration is invalid; nothing has run."""


class FatalError(RecoverError):
    """The run cannot continue."""


class InputError(FatalError):
    """A file the stage depends on as a whole does not hold what it should: `file`, the first
    bad `field` (None when the file does not parse at all) and every problem in the message."""

    def __init__(self, file, field: str | None, detail: str):
        super().__init__(f"{file}: {detail}")
        self.file = str(file)
        self.field = field
        self.detail = detail


def invalid_file(file, e: Exception, where: str = "") -> InputError:
    """An InputError for a pydantic ValidationError (every bad field listed, the first one kept
    as `field`) or any other parse error (JSON, a wrong type). `where` prefixes the field
    (e.g. "row 3.") for files with many records."""
    if isinstance(e, ValidationError):
        fields = [where + (".".join(str(p) for p in err["loc"]) or "<root>") for err in e.errors()]
        detail = "; ".join(f"field {f}: {err['msg']}" for f, err in zip(fields, e.errors(), strict=True))
        return InputError(file, fields[0] if fields else None, detail)
    field = where.rstrip(".") or None
    return InputError(file, field, f"{f'{field}: ' if field else ''}{type(e).__name__}: {e}")


class EpisodeError(RecoverError):
    """One unit of work failed; record `reason` and continue with the others."""

    def __init__(self, reason: str, detail: str = "", file: str | None = None, field: str | None = None):
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason
        self.detail = detail
        self.file = file  # the input at fault, when one is (becomes QuarantineEntry.file / .field)
        self.field = field


class RetryableError(RecoverError):
    """A transient failure; the caller may retry after `retry_after` seconds."""

    def __init__(self, message: str, retry_after: float | None = None):
        super().__init__(message)
        self.retry_after = retry_after
