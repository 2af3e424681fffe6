"""Killing a real stage-1 worker from outside, as `kill -9` or the OOM killer would.

Used by tests/executors/test_stage1_worker_killed.py and benchmarks/bad_inputs.py.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path


def pool_workers() -> list[int]:
    """This process's spawned pool workers (not multiprocessing's resource tracker)."""
    out = []
    for task in Path(f"/proc/{os.getpid()}/task").iterdir():
        for pid in (task / "children").read_text().split():
            try:
                if b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes():
                    out.append(int(pid))
            except FileNotFoundError:
                pass
    return out


def kill_a_worker_after_the_first_episode(done_dir: Path, timeout_s: float = 300) -> tuple[threading.Thread, list[int]]:
    """Start a thread that SIGKILLs one pool worker once the first done marker appears in
    `done_dir` (with two shards, both workers are inside theirs then). Returns the thread
    and the list it appends the killed pid to."""
    killed: list[int] = []

    def kill() -> None:
        deadline = time.time() + timeout_s
        while time.time() < deadline and not list(done_dir.glob("*.done")):
            time.sleep(0.05)
        pid = pool_workers()[0]
        os.kill(pid, signal.SIGKILL)
        killed.append(pid)

    thread = threading.Thread(target=kill, daemon=True)
    thread.start()
    return thread, killed
