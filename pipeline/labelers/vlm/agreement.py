"""Agreement between two failure-onset localizers (a VLM vs. the simulator-state rules).

Input: pairs (vlm_time_s, simstate_time_s) for episodes where both produced a time
(quarantined answers are simply not paired). Output: `Agreement` with the count, the mean
absolute error in seconds and the shares within +-0.5 s and +-1 s (inclusive; differences
are rounded to 1 ms first so 0.1-s answers on the boundary count as within). Empty input
gives n=0 and None statistics, never a division by zero.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from pydantic import BaseModel, ConfigDict

TOLERANCES_S = (0.5, 1.0)


class Agreement(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    n: int
    mae_s: float | None
    within_0_5s: float | None
    within_1s: float | None


def agreement(pairs: Iterable[tuple[float, float]]) -> Agreement:
    diffs = []
    for a, b in pairs:
        if not (math.isfinite(a) and math.isfinite(b)):
            raise ValueError(f"non-finite time in pair ({a}, {b})")
        diffs.append(round(abs(a - b), 3))
    if not diffs:
        return Agreement(n=0, mae_s=None, within_0_5s=None, within_1s=None)
    n = len(diffs)
    return Agreement(
        n=n,
        mae_s=sum(diffs) / n,
        within_0_5s=sum(d <= 0.5 for d in diffs) / n,
        within_1s=sum(d <= 1.0 for d in diffs) / n,
    )
