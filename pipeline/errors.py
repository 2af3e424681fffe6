"""Errors named by what the runner should do with them.

- ConfigError: fail before any work starts (bad file, unknown key, bad value).
- FatalError: stop the whole run (broken install, simulator missing).
- EpisodeError: record the reason for this unit of work and go on.
- RetryableError: back off and try again (a VLM server's 429/503, a timeout).
"""

from __future__ import annotations


class RecoverError(Exception):
    """Base of all project errors."""


class ConfigError(RecoverError):
    """Configuration is invalid; nothing has run."""


class FatalError(RecoverError):
    """The run cannot continue."""


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
