"""Top-level work functions for executor tests (spawned workers import them by name)."""

from __future__ import annotations

import os


def square(item, ctx):
    ctx.emit({"item": item, "pid": os.getpid()})
    return item * item


def read_env(item, ctx):
    return os.environ.get(item)


def explode(item, ctx):
    if item == 2:
        raise ValueError(f"item {item} is broken")
    return item


def write_once(item, ctx):
    """Fault-test work: `item` is (folder, name, mode); writes folder/out/<name> atomically.

    mode "first": SIGKILL its own worker on the first attempt (a marker file in folder/died
    remembers it); "always": on every attempt; "wait:<other>": stay in flight until <other>'s
    worker has died (so a death provably happens while this item runs). Each attempt appends
    a line to folder/attempts/<name>, so a test can count how often an item ran.
    """
    import signal
    import time
    from pathlib import Path

    from pipeline.atomic import write_text

    folder, name, mode = item
    folder = Path(folder)
    (folder / "attempts").mkdir(parents=True, exist_ok=True)
    with open(folder / "attempts" / name, "a") as f:
        f.write(f"{os.getpid()}\n")
    ctx.emit({"item": name, "pid": os.getpid()})
    marker = folder / "died" / name
    if mode == "always" or (mode == "first" and not marker.exists()):
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.touch()
        os.kill(os.getpid(), signal.SIGKILL)
    if mode.startswith("wait:"):
        deadline = time.time() + 60
        while not (folder / "died" / mode[5:]).exists() and time.time() < deadline:
            time.sleep(0.01)
        time.sleep(0.2)  # still running when the caller sees the other worker die
    write_text(folder / "out" / name, f"{name}\n")
    return name


def slow_write(item, ctx):
    """Ray fault-test work: (folder, name, seconds) -> sleeps, then writes folder/<name> atomically."""
    import time
    from pathlib import Path

    import ray

    from pipeline.atomic import write_text

    folder, name, seconds = item
    ctx.emit({"item": name, "node": ray.get_runtime_context().get_node_id()})
    time.sleep(seconds)
    write_text(Path(folder) / name, f"{name}\n")
    return name


_RUN_HERE = 0  # items this worker process has run: module globals live as long as the worker


def counted(item, ctx):
    global _RUN_HERE
    _RUN_HERE += 1
    return os.getpid(), _RUN_HERE


class _Kept:
    builds = 0  # per worker process

    def __init__(self):
        type(self).builds += 1
        self.uses = 0

    def close(self) -> None:
        pass


def context_kept(item, ctx):
    """(pid, helpers built in this worker, uses of this context's helper): a worker that keeps its
    WorkerContext across items builds the helper once (as stage 1 does its env and render process)."""
    h = ctx.helper("kept", _Kept)
    h.uses += 1
    return os.getpid(), _Kept.builds, h.uses
