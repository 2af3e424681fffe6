from __future__ import annotations

import numpy as np
import pytest

from pipeline.atomic import Completions, atomic_path, write_json, write_with


def test_failed_write_leaves_no_file_and_no_temporary(tmp_path):
    target = tmp_path / "out" / "a.json"
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("crash mid-write")
    assert not target.exists()
    assert list(target.parent.iterdir()) == []


def test_failed_rewrite_keeps_the_previous_version(tmp_path):
    target = tmp_path / "a.json"
    write_json(target, {"v": 1})
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("{broken")
            raise RuntimeError
    assert target.read_text().strip().endswith("}") and '"v": 1' in target.read_text()


def test_write_with_keeps_the_suffix_numpy_needs(tmp_path):
    target = tmp_path / "s.npy"
    write_with(target, lambda p: np.save(p, np.arange(3)))
    np.testing.assert_array_equal(np.load(target), np.arange(3))


def test_completions_mark_and_list_units(tmp_path):
    c = Completions(tmp_path)
    assert not c.is_done("u1") and c.done_ids() == set()
    c.mark_done("u1", {"steps": 3})
    c.mark_done("u2")
    assert c.is_done("u1") and c.done_ids() == {"u1", "u2"}


def test_a_marker_write_killed_midway_leaves_a_temp_file_that_is_no_done_unit(tmp_path):
    from pipeline.atomic import Completions

    done = Completions(tmp_path)
    done.mark_done("a")
    (done.dir / ".b.done.x1y2.done").write_text("")  # what a SIGKILL between mkstemp and rename leaves
    assert done.done_ids() == {"a"}
