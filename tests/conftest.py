"""Shared test setup: headless rendering and LIBERO's config before anything imports it."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from pipeline.sim.libero_setup import ensure_libero_ready  # noqa: E402

ensure_libero_ready()
