"""Errors of the review workflow, named by the HTTP answer they become.

Each carries a message for people and, where it helps a client act, the field at fault
(422) or the current version (409), so a page can reload instead of overwriting.
"""

from __future__ import annotations


class ReviewError(Exception):
    status = 400

    def __init__(self, message: str, *, field: str | None = None, current: dict | None = None):
        super().__init__(message)
        self.message = message
        self.field = field
        self.current = current

    def headers(self) -> dict | None:
        return None

    def body(self) -> dict:
        out: dict = {"detail": self.message}
        if self.field is not None:
            out["field"] = self.field
        if self.current is not None:
            out["current"] = self.current
        return out


class NotFound(ReviewError):
    status = 404


class Forbidden(ReviewError):
    status = 403


class Stale(ReviewError):
    """The write was based on an outdated view (or the item no longer takes it)."""

    status = 409


class Invalid(ReviewError):
    status = 422


class TooManyRequests(ReviewError):
    """Too many failed sign-ins from this client: retry after `retry_after` seconds."""

    status = 429

    def __init__(self, message: str, retry_after: int):
        super().__init__(message)
        self.retry_after = retry_after

    def headers(self) -> dict:
        return {"Retry-After": str(self.retry_after)}
