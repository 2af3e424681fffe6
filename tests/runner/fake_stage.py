"""A tiny pure-Python Stage for runner tests: no simulator, real files, real workers.

Units are names; a unit reads `in/<name>` (its input), writes `out/<name>` atomically and
records in `runs/<name>` the pid and the number of units its worker's context has run.
`modes` makes a unit fail ("fail": raises, set aside) or kill its own worker ("die": on
its first attempt, "always": on every one), or raise `RetryableError` ("flaky": on its
first try, "busy": on every one).
"""

from __future__ import annotations

import os
import signal
from dataclasses import dataclass, field
from pathlib import Path

from pipeline.atomic import file_stamp, write_text
from pipeline.errors import RetryableError
from pipeline.runner import Stage, UnitResult, WorkerContext


class Counter:
    """A per-worker helper: counts the units its worker ran (what a cached env relies on) and
    leaves `closed/<pid>` behind when its worker closes its context."""

    def __init__(self, folder: Path):
        self.n, self.folder = 0, folder

    def close(self) -> None:
        write_text(self.folder / "closed" / str(os.getpid()), f"{self.n}\n")


@dataclass
class FakeStage(Stage):
    folder: str
    names: list[str]
    modes: dict[str, str] = field(default_factory=dict)
    name: str = "fake"

    @property
    def root(self) -> Path:
        return Path(self.folder)

    def units(self, cfg) -> list[str]:
        return list(self.names)

    def unit_id(self, unit: str) -> str:
        return unit

    def fingerprint(self, unit: str) -> str:
        return file_stamp(self.root / "in" / unit)

    def forget(self, unit: str) -> None:
        (self.root / "out" / unit).unlink(missing_ok=True)

    def process(self, unit: str, ctx: WorkerContext) -> UnitResult:
        mode = self.modes.get(unit, "")
        counter = ctx.helper("counter", lambda: Counter(self.root))
        counter.n += 1
        runs = self.root / "runs"
        runs.mkdir(parents=True, exist_ok=True)
        with open(runs / unit, "a") as f:
            f.write(f"{os.getpid()} {counter.n}\n")
        died = self.root / "died" / unit
        if mode == "always" or (mode == "die" and not died.exists()):
            died.parent.mkdir(parents=True, exist_ok=True)
            died.touch()
            os.kill(os.getpid(), signal.SIGKILL)
        if mode == "fail":
            raise ValueError(f"{unit} is broken")
        if mode == "busy" or (mode == "flaky" and len((runs / unit).read_text().splitlines()) == 1):
            raise RetryableError(f"{unit}: server busy (503)")
        text = (self.root / "in" / unit).read_text()
        write_text(self.root / "out" / unit, text.upper())
        return UnitResult(info={"chars": len(text)}, ok=not text.startswith("x"))

    def set_aside(self, unit: str, error: Exception) -> UnitResult:
        write_text(self.root / "aside" / f"{unit}.txt", f"{type(error).__name__}: {error}\n")
        return UnitResult.set_aside(type(error).__name__, str(error))

    def after_done(self, unit: str, result: UnitResult) -> None:
        (self.root / "aside" / f"{unit}.txt").unlink(missing_ok=True)


def make(folder: Path, names: list[str], modes: dict[str, str] | None = None) -> FakeStage:
    for n in names:
        if not (folder / "in" / n).exists():
            write_text(folder / "in" / n, f"{n} input")
    return FakeStage(str(folder), names, modes or {})
