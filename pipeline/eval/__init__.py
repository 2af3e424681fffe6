"""Recovery evaluation: the protocol (`protocol`), records, metrics (RSR, RC, RD) and reports."""
