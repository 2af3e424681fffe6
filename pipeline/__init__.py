"""libero-recover: mine real policy failures in LIBERO into a reviewed, restorable recovery benchmark."""

__version__ = "0.1.0"
SCHEMA_VERSION = 1
