"""H.264 settings under which the same frames give the same MP4 bytes, on any machine.

libx264's defaults do not. Its thread pool follows the cores the process may use, and the
bytes follow the thread count (benchmarks/h264_repeatability.py: every 256 px clip of a run
gave 2 files on 1 vs 2 cores, 4 files with 1-4 threads). And with threads on auto, encoding
the same clip again in one process can give another file (tests/release/test_h264.py; CI: a
1- and a 2-worker LeRobot export differed in one wrist video); with one thread and mb-tree
on, stage 1's old encoder gave different 64 px wrist videos in two runs of the same code, and
probes caught it for some clips, depending on what else the process had allocated, never
with mb-tree off. So: one thread, mb-tree off. Without mb-tree a file is larger at the
same crf; a higher crf gives back the size at the same PSNR (measured there). One thread
costs nothing here: the exporting and rendering workers already fill the cores.
"""

from __future__ import annotations


def repeatable(stream, crf: int, **options: str) -> None:
    """Make a PyAV libx264 `stream` encode deterministically at `crf` (mb-tree off, one
    thread); `options` are further x264 options (e.g. g="2")."""
    stream.codec_context.thread_count = 1
    stream.options = {"crf": str(crf), "x264-params": "mbtree=0", **options}
