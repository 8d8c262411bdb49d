"""scripts/track_loso.py: each fold's setting is chosen on the other sequences only; the bootstrap's interval."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bboxtune.agents.commands import track_loso


def _counts(idtp: float, idfp: float, idfn: float, mota: float = 0.2) -> dict[str, float]:
    return {"idtp": idtp, "idfp": idfp, "idfn": idfn, "num_switches": 4.0, "num_unique_objects": 8.0, "mota": mota,
            "idf1": 2 * idtp / (2 * idtp + idfp + idfn)}


def test_each_fold_chooses_on_the_other_sequences() -> None:
    # setting 0 is best on A and B, setting 1 on the much larger C: the folds holding out A or B choose setting 1
    # (C's counts dominate the others' overall IDF1), the fold holding out C chooses setting 0
    table = {"sort_kf": {s: _counts(50, 50, 50) for s in "ABC"}, "bytetrack_kf": {s: _counts(40, 60, 60) for s in "ABC"},
             "0": {"A": _counts(80, 20, 20), "B": _counts(80, 20, 20), "C": _counts(100, 900, 900)},
             "1": {"A": _counts(10, 90, 90), "B": _counts(60, 40, 40), "C": _counts(900, 100, 100)}}
    folds = track_loso.loso(table, 2)
    assert [f["setting"] for f in folds] == [1, 1, 0]
    assert folds[0]["idf1"] == pytest.approx(0.1) and folds[0]["d_idf1_sort_kf"] == pytest.approx(0.1 - 0.5)
    assert folds[2]["d_idf1_bytetrack_kf"] == pytest.approx(0.1 - 0.4)
    assert folds[0]["switches_per_identity"] == 0.5
    assert track_loso.overall_idf1([table["0"]["A"], table["0"]["B"]]) == pytest.approx(0.8)


def test_the_bootstrap_interval_covers_the_mean() -> None:
    deltas = np.array([0.02, -0.01, 0.03, 0.0, 0.01, 0.015])
    low, high, positive = track_loso.bootstrap(deltas, 2000, 0)
    assert low < deltas.mean() < high and low > deltas.min() and high < deltas.max() and 0.5 < positive <= 1.0
    assert track_loso.bootstrap(-np.abs(deltas) - 0.01, 500, 0)[2] == 0.0


def test_the_output_must_be_a_new_csv(tmp_path: Path, capsys) -> None:
    with pytest.raises(SystemExit) as err:
        track_loso.main(["--out", str(tmp_path / "loso.txt")])
    assert err.value.code == 2 and "--out" in capsys.readouterr().err
