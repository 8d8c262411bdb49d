from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "otb_eval.py"
OTB_ROOT = os.environ.get("OTB_ROOT")
needs_otb = pytest.mark.skipif(not OTB_ROOT, reason="OTB_ROOT is unset (CI: OTB_ROOT=../shared/data/otb)")

# seq-avg success AUC from shared/data/otb/SOURCES.md (the published OTB-100 values)
PUBLISHED_AUC = {
    "SiamRPN++": 0.696, "SiamBAN": 0.696, "Ocean-online": 0.684, "MDNet": 0.678, "Ocean": 0.671, "ATOM": 0.667,
    "DaSiamRPN": 0.658, "SiamRPN": 0.632, "CFNet": 0.587, "SiamFC": 0.587, "MUSTer": 0.571, "MEEM": 0.510,
    "STRUCK": 0.462,
}


def load_script():
    spec = importlib.util.spec_from_file_location("otb_eval", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def write_fixture(root: Path, tracker_line2: str = "2,2,10,10") -> Path:
    (root / "groundtruth").mkdir(parents=True)
    (root / "groundtruth" / "A.txt").write_text("1,1,10,10\n2,2,10,10\n")
    (root / "groundtruth" / "B.txt").write_text("5,5,20,20\n0,0,0,0\n")
    (root / "trackers" / "T").mkdir(parents=True)
    (root / "trackers" / "T" / "A.txt").write_text(f"1,1,10,10\n{tracker_line2}\n")
    (root / "trackers" / "T" / "B.txt").write_text("5,5,20,20\n9,9,9,9\n")
    return root


def test_json_output_on_a_fixture(tmp_path, capsys):
    root = write_fixture(tmp_path)
    assert load_script().main(["--otb-root", str(root), "--json"]) == 0
    table = json.loads(capsys.readouterr().out)
    assert set(table) == {"T"} and table["T"]["n_sequences"] == 2
    assert table["T"]["success_auc"] == pytest.approx(20 / 21)  # perfect on every annotated frame
    assert table["T"]["precision20"] == 1.0


def test_malformed_file_exits_with_one_line(tmp_path):
    root = write_fixture(tmp_path, tracker_line2="2,2,ten,10")
    run = subprocess.run([sys.executable, str(SCRIPT), "--otb-root", str(root), "--json"],
                         capture_output=True, text=True, env={**os.environ, "OTB_ROOT": ""})
    assert run.returncode == 2 and run.stdout == ""
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in run.stderr
    assert f"{root / 'trackers' / 'T' / 'A.txt'}:2:" in lines[0]


def test_missing_root_and_unknown_tracker_exit_nonzero(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("OTB_ROOT", raising=False)
    script = load_script()
    assert script.main([]) == 2
    assert script.main(["--otb-root", str(write_fixture(tmp_path)), "--tracker", "Nope"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "OTB_ROOT" in err[0] and "Nope" in err[1]


@needs_otb
def test_reproduces_published_otb100_success_auc(capsys):
    assert load_script().main(["--otb-root", OTB_ROOT, "--json"]) == 0
    table = json.loads(capsys.readouterr().out)
    assert set(table) == set(PUBLISHED_AUC)
    for tracker, auc in PUBLISHED_AUC.items():
        assert table[tracker]["success_auc"] == pytest.approx(auc, abs=0.005), tracker
        assert table[tracker]["n_sequences"] == (73 if tracker in ("MEEM", "MUSTer") else 100)
    assert table["SiamRPN++"]["precision20"] == pytest.approx(0.905, abs=0.005)
