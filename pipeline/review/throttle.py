"""Throttling of failed sign-ins, per client: a small token bucket of failures.

Inputs: the client's address (the socket's peer; behind a proxy, uvicorn's
`--proxy-headers` with `--forwarded-allow-ips` makes it the real client), the outcome.
Invariants:
- a client may fail `burst` times at once, then once per `refill_s` seconds; while its
  bucket is empty every request that carries credentials (a token to sign in with, a bearer
  token, a session cookie) is answered 429 with Retry-After *before* the credentials are
  looked at, so a throttled guesser learns nothing, not even from a right guess;
- only failures cost: people who sign in correctly are never slowed;
- the buckets live in the server process (each of `--workers N` keeps its own, so a client
  gets N times the rate at most) and at most `max_clients` are kept (least recent dropped).
"""

from __future__ import annotations

import math
import threading
import time
from collections import OrderedDict


class FailureThrottle:
    def __init__(self, burst: int = 10, refill_s: float = 6.0, max_clients: int = 10_000):
        self.burst, self.refill_s, self.max_clients = burst, refill_s, max_clients
        self._buckets: OrderedDict[str, tuple[float, float]] = OrderedDict()  # client -> (tokens, at)
        self._guard = threading.Lock()

    def _tokens(self, client: str, t: float) -> float:
        tokens, at = self._buckets.get(client, (float(self.burst), t))
        return min(float(self.burst), tokens + (t - at) / self.refill_s)

    def retry_after(self, client: str) -> int:
        """Seconds until `client` may try again (0: now)."""
        with self._guard:
            tokens = self._tokens(client, time.monotonic())
        return 0 if tokens >= 1 else max(1, math.ceil((1 - tokens) * self.refill_s))

    def failed(self, client: str) -> None:
        t = time.monotonic()
        with self._guard:
            self._buckets[client] = (max(0.0, self._tokens(client, t) - 1), t)
            self._buckets.move_to_end(client)
            while len(self._buckets) > self.max_clients:
                self._buckets.popitem(last=False)
