"""H.264 settings under which the same frames give the same MP4 bytes, on any machine.

libx264's defaults do not (benchmarks/h264_repeatability.py, PyAV 18 here): its mb-tree
rate control reads lookahead memory it has not written at some frame sizes, so encoding the
same 24 frames again and again in one process gives several different files at 64 and 96 px
(never at 256 px in the runs so far); and its frame threads make the bytes depend on the
thread count, which x264 takes from the machine's cores. One thread and mb-tree off give
one file for every clip, size and thread setting tried. Without mb-tree a file is larger
at the same crf; two crf steps up gives about the same size and PSNR (measured there).

Repeatable bytes are what let a 1-worker and a 2-worker export, or a rerun, be compared
byte for byte. One thread costs nothing here: the exporting workers already fill the cores.
"""

from __future__ import annotations

def repeatable(stream, crf: int, **options: str) -> None:
    """Make a PyAV libx264 `stream` encode deterministically at `crf` (mb-tree off, one
    thread); `options` are further x264 options (e.g. g="2")."""
    stream.codec_context.thread_count = 1
    stream.options = {"crf": str(crf), "x264-params": "mbtree=0", **options}
