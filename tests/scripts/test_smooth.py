"""scripts/smooth.py: smoothed result files (same names, one line per input line) with the tuner's parameters, the
default tracker-output tuner, raw vs smoothed scores by otb_eval's scorer, and misuse (exit 2, one line, nothing
written)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from bboxtune.agents.commands import otb_eval
from bboxtune.agents.commands import smooth as smooth_script
from bboxtune.agents.policies.gate_file import GATE_FILE, Gate, LinearGain, write_gate
from bboxtune.agents.smoothing import pretrained
from bboxtune.agents.smoothing.tuner import Tuner, load_pretrained
from bboxtune.envs.data.otb import OTBDataset
from bboxtune.envs.data.otb_io import read_boxes

from .cli_misuse import check_misuse, misuse
from .tiny_run import REPO

TAU = "0.04"


def _track(seed: int, T: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(T)
    centre = np.stack([100 + 3.0 * t, 80 + 10 * np.sin(t / 5)], axis=1)
    size = np.array([30.0, 50.0])
    truth = np.concatenate([centre - size / 2, np.broadcast_to(size, (T, 2))], axis=1)
    return truth, truth + np.concatenate([rng.normal(0, 2, (T, 2)), rng.normal(0, 1, (T, 2))], axis=1)


def write_results(folder: Path) -> dict[str, np.ndarray]:
    """Three small result files: comma-separated, tab-separated with integer values, and one whose first frames
    and a middle stretch are 0,0,0,0 (no box). Returns the boxes as read back."""
    folder.mkdir(parents=True)
    _, a = _track(0, 40)
    _, b = _track(1, 30)
    _, c = _track(2, 50)
    (folder / "Alpha.txt").write_text("\n".join(",".join(f"{v:.2f}" for v in row) for row in a) + "\n")
    (folder / "beta_1.txt").write_text("\n".join("\t".join(f"{v:.0f}" for v in row) for row in b) + "\n")
    lines = [",".join(f"{v:.2f}" for v in row) for row in c]
    lines[:2] = ["0,0,0,0"] * 2
    lines[20:24] = ["0,0,0,0"] * 4
    (folder / "Gamma.txt").write_text("\n".join(lines) + "\n")
    (folder / "notes.md").write_text("not a result file\n")
    return {p.name: read_boxes(p) for p in sorted(folder.glob("*.txt"))}


def write_otb(root: Path) -> None:
    """A tiny OTB data set (shared layout) with the ground truth of the three sequences."""
    (root / "groundtruth").mkdir(parents=True)
    for seed, name, T in ((0, "Alpha", 40), (1, "Beta-1", 30), (2, "Gamma", 50)):
        truth, _ = _track(seed, T)
        (root / "groundtruth" / f"{name}.txt").write_text("\n".join(",".join(f"{v:.3f}" for v in r) for r in truth) + "\n")


def run(*args: str) -> int:
    return smooth_script.main([str(a) for a in args])


def test_smoothed_files_hold_the_tuners_estimates(tmp_path, capsys):
    raw = write_results(tmp_path / "SiamX")
    out = tmp_path / "out"
    assert run("--results", tmp_path / "SiamX", "--out", out, "--pretrained", "sim_ufir_cmn", "--tau", TAU) == 0
    assert sorted(p.name for p in out.iterdir()) == ["Alpha.txt", "Gamma.txt", "beta_1.txt", "params.csv"]
    tuner = load_pretrained("sim_ufir_cmn")
    table = {row.split(",")[0]: row.split(",") for row in (out / "params.csv").read_text().splitlines()}
    assert table.pop("sequence") == ["sequence", "n_frames", "n_missing_in", "n_missing_out", "left_alone", "psi", "horizon"]
    for name, boxes in raw.items():
        params = tuner.tune(boxes, float(TAU))
        expected = tuner.smooth(boxes, float(TAU), params)
        text_lines = (out / name).read_text().splitlines()
        assert len(text_lines) == len(boxes)
        written = read_boxes(out / name)
        np.testing.assert_allclose(written, expected, atol=5.1e-4)  # 3 decimals; NaN rows where no estimate
        row = table[Path(name).stem]
        n_in = int(np.isnan(boxes).any(axis=1).sum())
        assert row[1:5] == [str(len(boxes)), str(n_in), str(int(np.isnan(expected).any(axis=1).sum())), "0"]
        assert float(row[5]) == params["psi"] and int(row[6]) == params["horizon"]
    gamma = read_boxes(out / "Gamma.txt")
    assert np.isnan(gamma[:2]).all() and np.isfinite(gamma[2:]).all()  # the gap is predicted, the start is not
    assert table["Gamma"][2:4] == ["6", "2"]
    assert "smoothed 3 of 3 sequences with sim_ufir_cmn" in capsys.readouterr().out


def write_gate_file(path: Path, margin: float) -> Path:
    """A gate for a 20-feature tuner whose prediction is 0 everywhere, with ``margin``."""
    zeros = LinearGain(np.zeros(20), np.ones(20), np.zeros(20), 0.0)
    write_gate(path, Gate(zeros, margin), about="test")
    return path


def test_a_gate_writes_the_sequences_it_leaves_alone_as_read(tmp_path, capsys):
    """--gate FILE (or a gate.json in the tuner's folder): where the gate stays closed the sequence is written as read
    (left_alone 1), where it opens exactly as without a gate."""
    raw = write_results(tmp_path / "SiamX")
    common = ("--results", tmp_path / "SiamX", "--pretrained", "sim_ufir_cmn", "--tau", TAU)
    assert run(*common, "--out", tmp_path / "plain") == 0
    assert run(*common, "--out", tmp_path / "open", "--gate", write_gate_file(tmp_path / "open.json", -np.inf)) == 0
    for name in ("Alpha.txt", "beta_1.txt", "Gamma.txt"):
        assert (tmp_path / "open" / name).read_text() == (tmp_path / "plain" / name).read_text()
    assert run(*common, "--out", tmp_path / "alone", "--gate", write_gate_file(tmp_path / "closed.json", 0.0)) == 0
    assert "smoothed 0 of 3 sequences with sim_ufir_cmn (ufir_cmn, tau 0.04 s); the gate left 3 as read" in \
        capsys.readouterr().out
    table = [row.split(",") for row in (tmp_path / "alone" / "params.csv").read_text().splitlines()[1:]]
    assert [row[4] for row in table] == ["1", "1", "1"]
    for name, boxes in raw.items():
        np.testing.assert_array_equal(read_boxes(tmp_path / "alone" / name), boxes)  # missing frames stay missing
        # byte for byte: tabs and integers (beta_1), 0,0,0,0 rows (Gamma), the final newline, all as read
        assert (tmp_path / "alone" / name).read_bytes() == (tmp_path / "SiamX" / name).read_bytes()
    folder = tmp_path / "gated_tuner"
    shutil.copytree(REPO / "agents/pretrained/sim_ufir_cmn", folder)
    write_gate_file(folder / GATE_FILE, np.inf)
    tuner = Tuner.from_run(folder)
    boxes = raw["Gamma.txt"]
    assert tuner.gate is not None and tuner.leaves_alone(tuner.observe(boxes, 0.04))
    np.testing.assert_array_equal(tuner.smooth(boxes, 0.04), boxes)
    assert tuner.tune(boxes, 0.04) == load_pretrained("sim_ufir_cmn").tune(boxes, 0.04)  # the model's parameters
    assert run("--results", tmp_path / "SiamX", "--model", folder, "--tau", TAU, "--out", tmp_path / "folder_gate") == 0
    assert run("--results", tmp_path / "SiamX", "--model", folder, "--tau", TAU, "--out", tmp_path / "no_gate",
               "--no-gate") == 0
    for name in ("Alpha.txt", "beta_1.txt", "Gamma.txt"):
        assert (tmp_path / "folder_gate" / name).read_text() == (tmp_path / "alone" / name).read_text()
        assert (tmp_path / "no_gate" / name).read_text() == (tmp_path / "plain" / name).read_text()


def test_default_tuner_is_the_tracker_output_one(tmp_path, monkeypatch, capsys):
    write_results(tmp_path / "SiamX")
    monkeypatch.setattr(pretrained, "ROOT", tmp_path / "shipped")
    (tmp_path / "shipped").mkdir()
    with pytest.raises(SystemExit) as info:
        run("--results", tmp_path / "SiamX", "--out", tmp_path / "out")
    assert info.value.code == 2 and not (tmp_path / "out").exists()
    assert "--pretrained: pretrained tuner 'otb_tracker_kf_cmn' is not installed" in capsys.readouterr().err
    shutil.copytree(REPO / "agents/pretrained/sim_kf_cmn", tmp_path / "shipped/otb_tracker_kf_cmn")
    assert run("--results", tmp_path / "SiamX", "--out", tmp_path / "out", "--tau", TAU) == 0
    assert "with otb_tracker_kf_cmn (kf_cmn" in capsys.readouterr().out
    reference = tmp_path / "reference"
    run("--results", tmp_path / "SiamX", "--out", reference, "--model", REPO / "docs/results/kf_cmn/run", "--tau", TAU)
    for name in ("Alpha.txt", "beta_1.txt", "Gamma.txt", "params.csv"):
        assert (tmp_path / "out" / name).read_text() == (reference / name).read_text()


def test_otb_root_scores_raw_and_smoothed_with_otb_evals_scorer(tmp_path, capsys):
    write_results(tmp_path / "trackers" / "SiamX")
    write_otb(tmp_path / "otb")
    out = tmp_path / "out"
    assert run("--results", tmp_path / "trackers/SiamX", "--out", out, "--pretrained", "sim_kf_cmn",
               "--otb-root", tmp_path / "otb", "--tau", TAU) == 0
    printed = capsys.readouterr().out
    scores = [line.split(",") for line in (out / "scores.csv").read_text().splitlines()]
    assert scores[0] == ["results", "n_sequences", "success_auc", "precision20"]
    shutil.copytree(out, tmp_path / "trackers" / "smoothed", ignore=shutil.ignore_patterns("*.csv"))
    dataset = OTBDataset(tmp_path / "otb", trackers_root=tmp_path / "trackers")
    expected = otb_eval.evaluate(dataset, ["SiamX", "smoothed"])
    for row, key in zip(scores[1:], ("SiamX", "smoothed"), strict=False):
        assert int(row[1]) == expected[key]["n_sequences"] == 3
        assert float(row[2]) == pytest.approx(expected[key]["success_auc"], abs=1e-6)
        assert float(row[3]) == pytest.approx(expected[key]["precision20"], abs=1e-6)
        assert f"{expected[key]['success_auc']:.3f}" in printed
    assert scores[1][2] != scores[2][2]  # smoothing changed the boxes


@pytest.fixture
def results(misuse_paths) -> Path:
    """A valid results folder for the misuse cases (``{results}``), plus malformed ones."""
    folder = misuse_paths.root / "results"
    write_results(folder)
    misuse_paths.names["results"] = str(folder)
    for name, text in (("bad_line", "1,2,3,4\n1,2,3,4\n1,2,x,4\n"), ("short", "1,2,3,4\n" * 5),
                       ("negative", "1,2,3,4\n" * 9 + "1,2,-3,4\n"), ("huge", "1,2,3,4\n" * 9 + "1e300,2,3,4\n")):
        bad = misuse_paths.root / name
        shutil.copytree(folder, bad)
        (bad / "Zeta.txt").write_text(text)
        misuse_paths.names[name] = str(bad)
    full = misuse_paths.root / "full"
    full.mkdir()
    (full / "x").write_text("taken\n")
    misuse_paths.names["full"] = str(full)
    return folder


BASE = ("--results", "{results}", "--out", "{out}")
CASES = [
    misuse(mentions="--results"),
    misuse("--out", "{out}", mentions="--results"),
    misuse("--results", "{results}", mentions="--out"),
    misuse("--results", "{missing}", "--out", "{out}", mentions="--results"),
    misuse("--results", "{file}", "--out", "{out}", mentions="--results"),
    misuse("--results", "{dir}", "--out", "{out}", mentions="--results"),  # no result files in it
    misuse("--results", "{bad_line}", "--out", "{out}", mentions="{bad_line}/Zeta.txt:3"),
    misuse("--results", "{negative}", "--out", "{out}", mentions="{negative}/Zeta.txt:10"),
    misuse("--results", "{huge}", "--out", "{out}", mentions="{huge}/Zeta.txt:10: box [1e+300, 2.0, 3.0, 4.0] is too large"),
    misuse("--results", "{short}", "--out", "{out}", mentions="{short}/Zeta.txt has 5 frames"),
    misuse("--results", "{results}", "--out", "{under_file}"),
    misuse("--results", "{results}", "--out", "{file}"),
    misuse("--results", "{results}", "--out", "{full}", mentions="--out {full} exists and is not empty"),
    misuse(*BASE, "--pretrained", "nope", mentions="--pretrained: pretrained tuner 'nope' is not installed"),
    misuse(*BASE, "--pretrained", "sim_ufir_cmn", "--model", "{dir}", mentions="--model"),
    misuse(*BASE, "--model", "{dir}"),  # not a run directory
    misuse(*BASE, "--model", "{missing}"),
    *[misuse(*BASE, "--pretrained", "sim_ufir_cmn", "--tau", v) for v in ("0", "2", "nan", "inf", "abc", "1e-4")],
    misuse(*BASE, "--pretrained", "sim_ufir_cmn", "--otb-root", "{missing}"),
    misuse(*BASE, "--pretrained", "sim_ufir_cmn", "--otb-root", "{dir}"),
    misuse(*BASE, "--pretrained", "sim_ufir_cmn", "--otb-root", "{bad_json}", mentions="{bad_json}:2"),
    misuse(*BASE, "--pretrained", "sim_ufir_cmn", "--unknown"),
    misuse(*BASE, "--pretrained", "sim_ufir_cmn", "--gate", "{missing}", mentions="--gate"),
    misuse(*BASE, "--pretrained", "sim_ufir_cmn", "--gate", "{dir}", mentions="--gate"),
    misuse(*BASE, "--pretrained", "sim_ufir_cmn", "--gate", "{file}", mentions="{file}:1:1: invalid JSON"),
    misuse(*BASE, "--pretrained", "sim_ufir_cmn", "--gate", "{bad_json}", mentions="{bad_json}:2:7: invalid JSON"),
    misuse(*BASE, "--pretrained", "sim_ufir_cmn", "--gate", "{bad_json}", "--no-gate", mentions="--no-gate"),
    misuse("--res", "{results}", "--out", "{out}", mentions="--res"),  # flags are not abbreviated
]


@pytest.mark.parametrize("case", CASES, ids=str)
def test_misuse(case, results, misuse_paths, capsys, monkeypatch):
    check_misuse(smooth_script.main, case, misuse_paths, capsys, monkeypatch)


def test_a_folder_without_ground_truth_for_any_file_is_an_otb_root_error(tmp_path, results, misuse_paths, capsys,
                                                                          monkeypatch):
    root = misuse_paths.root / "otb"
    (root / "groundtruth").mkdir(parents=True)
    truth, _ = _track(9, 20)
    (root / "groundtruth" / "Other.txt").write_text("\n".join(",".join(map(str, r)) for r in truth) + "\n")
    case = misuse(*BASE, "--pretrained", "sim_ufir_cmn", "--otb-root", str(root), mentions="has no output file")
    check_misuse(smooth_script.main, case, misuse_paths, capsys, monkeypatch)
