"""bboxtune.agents.evaluation.video_tables: whole output folders published all or nothing; CSV text."""

from __future__ import annotations

import pytest

from bboxtune.agents.evaluation.video_tables import csv_text, publish_folder


def test_publish_folder_is_all_or_nothing(tmp_path):
    out = tmp_path / "out"
    out.mkdir()  # an empty folder is taken
    publish_folder(out, {"a.txt": "1", "sub/b.txt": "2"})
    assert (out / "sub" / "b.txt").read_text() == "2"
    with pytest.raises(ValueError, match="not empty"):  # a second run racing for it gets an error, not a mix
        publish_folder(out, {"a.txt": "changed", "c.txt": "3"})
    assert (out / "a.txt").read_text() == "1" and not (out / "c.txt").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # its temporary folder is gone
    (tmp_path / "file").write_text("x")
    with pytest.raises(ValueError, match="not a folder"):
        publish_folder(tmp_path / "file", {"a.txt": "1"})


def test_csv_text_rounds_floats_to_6_significant_digits():
    assert csv_text(["a", "b"], [[1.0 / 3, "x"], [2, 1e-7]]) == "a,b\n0.333333,x\n2,1e-07\n"
