"""scripts/mot_eval.py: the MOT15 identity table (bboxtune.agents.commands.mot_eval) and its refusals."""

from __future__ import annotations

import csv
import os
from pathlib import Path

import pytest

from bboxtune.agents.commands import mot_eval

MOT_ROOT = os.environ.get("MOT_ROOT")
needs_mot = pytest.mark.skipif(not MOT_ROOT, reason="MOT_ROOT is unset: the MOT15 table needs the MOT15 data "
                                                   "(CI: MOT_ROOT=../shared/data/mot15)")


@needs_mot
def test_table_on_the_test_split(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "table"
    assert mot_eval.main(["--mot-root", str(MOT_ROOT), "--split", "test", "--out", str(out),
                          "--pretrained", "otb_kf_cmn"]) == 0
    text = (out / "summary.md").read_text()
    assert "15 identities of KITTI-13" in text and text == capsys.readouterr().out
    rows = {line.split(" | ")[0].lstrip("| "): line for line in text.splitlines() if line.startswith("| ")}
    assert set(rows) >= {"raw", "bytetrack_kf", "sort_kf", "rule_kf", "rule_kf_cmn", "rule_ufir_cmn",
                         "bytetrack_oracle", "pretrained:otb_kf_cmn"}
    assert "+0.000 [+0.000, +0.000]" in rows["bytetrack_kf"]  # paired against itself
    with open(out / "per_identity.csv") as f:
        table = list(csv.DictReader(f))
    assert len(table) == 15 * 8 and {r["identity"].split("/")[0] for r in table} == {"KITTI-13"}
    raw = [r for r in table if r["method"] == "raw"]
    assert all(float(r["iou_gap_sum"]) == 0.0 for r in raw)  # the detections fill no gap
    oracle = {r["identity"]: r for r in table if r["method"] == "bytetrack_oracle"}
    stock = {r["identity"]: r for r in table if r["method"] == "bytetrack_kf"}
    # the oracle's grid holds the stock weights, so it is never below them on its own objective
    assert all(float(oracle[i]["iou_gap_sum"]) + 1e-9 >= 0 for i in oracle) and len(stock) == 15
    assert (out / "command.txt").read_text().startswith("python scripts/mot_eval.py --mot-root")


@needs_mot
def test_refuses_a_used_output_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "summary.md").write_text("mine")
    assert mot_eval.main(["--mot-root", str(MOT_ROOT), "--out", str(tmp_path)]) == 2
    assert "already holds summary.md" in capsys.readouterr().err
    assert (tmp_path / "summary.md").read_text() == "mine"


def test_refuses_a_missing_data_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stop:
        mot_eval.main(["--mot-root", str(tmp_path / "nowhere"), "--out", str(tmp_path / "o")])
    assert stop.value.code == 2 and "does not exist" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_refuses_a_folder_without_mot_data(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert mot_eval.main(["--mot-root", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "sequences.csv" in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_refuses_an_unknown_pretrained_tuner(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert mot_eval.main(["--mot-root", str(tmp_path), "--out", str(tmp_path / "o"), "--pretrained", "nope"]) == 2
    err = capsys.readouterr().err
    assert "'nope'" in err and "sequences.csv" not in err  # tuners are loaded before the data is read
    assert not (tmp_path / "o").exists()


@needs_mot
def test_gap_decay_rows_change_the_gap_frames_only(tmp_path: Path) -> None:
    out = tmp_path / "table"
    assert mot_eval.main(["--mot-root", str(MOT_ROOT), "--split", "test", "--out", str(out), "--pretrained",
                          "mot15_det", "--gap-decay", "1", "1", "--gap-decay", "0.5", "0"]) == 0
    with open(out / "per_identity.csv") as f:
        table = list(csv.DictReader(f))
    by = {name: [r for r in table if r["method"] == name] for name in {r["method"] for r in table}}
    assert set(by) >= {"bytetrack_kf gap(1.0, 1.0)", "bytetrack_kf gap(0.5, 0.0)", "pretrained:mot15_det",
                       "pretrained:mot15_det gap(1.0, 1.0)", "pretrained:mot15_det gap(0.5, 0.0)"}
    assert by["bytetrack_kf gap(1.0, 1.0)"] == [r | {"method": "bytetrack_kf gap(1.0, 1.0)"} for r in by["bytetrack_kf"]]
    for tuned, stock in [("bytetrack_kf gap(0.5, 0.0)", "bytetrack_kf"),
                         ("pretrained:mot15_det gap(0.5, 0.0)", "pretrained:mot15_det gap(1.0, 1.0)")]:
        pairs = list(zip(by[tuned], by[stock], strict=True))
        assert all(a["iou_detected"] == b["iou_detected"] and a["sq_detected"] == b["sq_detected"] for a, b in pairs)
        assert any(a["iou_gap_sum"] != b["iou_gap_sum"] for a, b in pairs)


def test_refuses_a_gap_decay_out_of_range(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert mot_eval.main(["--mot-root", str(tmp_path), "--out", str(tmp_path / "o"), "--gap-decay", "1.5", "0"]) == 2
    err = capsys.readouterr().err
    assert "--gap-decay: gap_velocity_decay=1.5 is out of range" in err and "sequences.csv" not in err
    assert not (tmp_path / "o").exists()
