"""Session fixtures of the release tests (factories live in `factories.py`)."""

from __future__ import annotations

from tests.release.factories import scene_source  # noqa: F401  (a session fixture)
