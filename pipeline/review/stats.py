"""Agreement statistics, written from the definitions (no stats package).

Inputs: ratings as plain Python lists.
Outputs: floats (nan when undefined, e.g. no variation at all).
- `cohen_kappa(a, b)`: two raters, nominal.
- `fleiss_kappa(counts)`: counts[item][category], the same number of raters per item.
- `krippendorff_alpha(units, metric, order)`: any number of raters, missing values
  allowed (units are lists of the values given for one item); metric nominal, ordinal
  (ranks from `order`, distances from the marginal frequencies) or interval.
- `within_tolerance(units, tau)`: share of items whose values all lie within tau.
- `confusion(pairs, labels)`: rows = final (truth), columns = model.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Hashable, Sequence

NAN = float("nan")


def cohen_kappa(a: Sequence[Hashable], b: Sequence[Hashable]) -> float:
    if len(a) != len(b):
        raise ValueError(f"raters rated different numbers of items ({len(a)} vs {len(b)})")
    n = len(a)
    if n == 0:
        return NAN
    po = sum(x == y for x, y in zip(a, b)) / n
    ca, cb = Counter(a), Counter(b)
    pe = sum(ca[k] * cb[k] for k in ca) / (n * n)
    return NAN if pe == 1 else (po - pe) / (1 - pe)


def fleiss_kappa(counts: Sequence[Sequence[int]]) -> float:
    if not counts:
        return NAN
    raters = {sum(row) for row in counts}
    if len(raters) != 1 or min(raters) < 2:
        raise ValueError(f"every item needs the same number (>= 2) of raters, got {sorted(raters)}")
    r, n = raters.pop(), len(counts)
    p_items = [(sum(c * c for c in row) - r) / (r * (r - 1)) for row in counts]
    p_bar = sum(p_items) / n
    totals = [sum(row[j] for row in counts) for j in range(len(counts[0]))]
    pe = sum((t / (n * r)) ** 2 for t in totals)
    return NAN if pe == 1 else (p_bar - pe) / (1 - pe)


def krippendorff_alpha(units: Sequence[Sequence], metric: str = "nominal", order: Sequence | None = None) -> float:
    pairable = [[v for v in u if v is not None] for u in units]
    pairable = [u for u in pairable if len(u) >= 2]
    if metric == "ordinal":
        if order is None:
            order = sorted({v for u in pairable for v in u})
        rank = {v: i for i, v in enumerate(order)}
        pairable = [[rank[v] for v in u] for u in pairable]
    # coincidences: every ordered pair of values within a unit, weighted 1/(m_u - 1)
    o: Counter = Counter()
    for u in pairable:
        m = len(u)
        for i in range(m):
            for j in range(m):
                if i != j:
                    o[(u[i], u[j])] += 1 / (m - 1)
    nc: Counter = Counter()
    for (c, _k), w in o.items():
        nc[c] += w
    n = sum(nc.values())
    if n <= 1:
        return NAN
    values = sorted(nc)

    def d2(c, k) -> float:
        if metric == "nominal":
            return 0.0 if c == k else 1.0
        if metric == "interval":
            return float(c - k) ** 2
        if metric == "ordinal":
            lo, hi = min(c, k), max(c, k)
            return (sum(nc[g] for g in values if lo <= g <= hi) - (nc[c] + nc[k]) / 2) ** 2
        raise ValueError(f"metric must be nominal, ordinal or interval, got {metric!r}")

    observed = sum(w * d2(c, k) for (c, k), w in o.items())
    expected = sum(nc[c] * nc[k] * d2(c, k) for c in values for k in values)
    if expected == 0:
        return NAN
    return 1 - (n - 1) * observed / expected


def within_tolerance(units: Sequence[Sequence[float]], tau: float) -> float:
    rated = [u for u in units if len(u) >= 2]
    if not rated:
        return NAN
    return sum(max(u) - min(u) <= tau + 1e-9 for u in rated) / len(rated)


def confusion(pairs: Sequence[tuple[Hashable, Hashable]], labels: Sequence[Hashable]) -> list[list[int]]:
    idx = {lab: i for i, lab in enumerate(labels)}
    m = [[0] * len(labels) for _ in labels]
    for truth, model in pairs:
        if truth in idx and model in idx:
            m[idx[truth]][idx[model]] += 1
    return m


def clean(x: float) -> float | None:
    """JSON has no NaN: undefined statistics become null."""
    return None if x is None or (isinstance(x, float) and math.isnan(x)) else round(x, 4)
