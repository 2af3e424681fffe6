"""Retries of `RetryableError`, the one error kind that says "back off and try again".

`call_with_retries` runs one unit's work up to `policy.tries` times in its worker, sleeping
`backoff_s`, 2x, 4x ... (at most `max_backoff_s`; an error's own `retry_after` is honoured
within the same cap) between tries and reporting each lost try through `on_retry` (the
runner turns it into a `retry` Event). After the last try it re-raises the error, and the
stage sets the unit aside. Any other exception passes through at once: retrying cannot fix
a bug or bad input. A dead worker is a different fault, retried by the executor.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

from pipeline.config import RetryConfig
from pipeline.errors import RetryableError

T = TypeVar("T")


def backoff(policy: RetryConfig, lost: int, error: RetryableError) -> float:
    """Seconds to wait after losing try number `lost` (1 = the first)."""
    wait = policy.backoff_s * 2 ** (lost - 1)
    if error.retry_after is not None:
        wait = max(wait, error.retry_after)
    return min(wait, policy.max_backoff_s)


def call_with_retries(work: Callable[[], T], policy: RetryConfig,
                      on_retry: Callable[[int, RetryableError, float], None] = lambda k, e, w: None,
                      sleep: Callable[[float], None] = time.sleep) -> T:
    """`work()`, tried again on RetryableError; `on_retry(lost_try, error, wait_s)` before each wait."""
    for k in range(1, policy.tries + 1):
        try:
            return work()
        except RetryableError as e:
            if k == policy.tries:
                raise
            wait = backoff(policy, k, e)
            on_retry(k, e, wait)
            sleep(wait)
    raise AssertionError("unreachable: tries >= 1")
