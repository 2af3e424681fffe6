"""Top-level work functions for executor tests (spawned workers import them by name)."""

from __future__ import annotations

import os


def square(item, emit):
    emit({"item": item, "pid": os.getpid()})
    return item * item


def read_env(item, emit):
    return os.environ.get(item)


def explode(item, emit):
    if item == 2:
        raise ValueError(f"item {item} is broken")
    return item
