"""scripts/eval_mot.py: motmetrics' table of a results folder against a MOT15-layout ground-truth folder, the CSV,
and its misuse cases (exit 2, one line naming the flag or ``file:line``, nothing written; ``cli_misuse.py``)."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from bboxtune.agents.commands import eval_mot
from bboxtune.agents.evaluation import mot_metrics

from ..agents.evaluation.test_mot_metrics import EXPECTED, FLAG0_ROW, GT_ROWS, RESULT_ROWS
from .cli_misuse import MisusePaths, check_misuse, misuse, misuse_paths, run_script  # noqa: F401  (fixture)

SEQUENCES = ("ADL-Rundle-6", "KITTI-13")


def make_data(root: Path, sequences: tuple[str, ...] = SEQUENCES) -> tuple[Path, Path]:
    """``root/gt/<SEQ>/gt/gt.txt`` and ``root/results/<SEQ>.txt``: the hand-made case of test_mot_metrics in each."""
    gt_root, results = root / "gt", root / "results"
    results.mkdir(parents=True)
    for name in sequences:
        (gt_root / name / "gt").mkdir(parents=True)
        (gt_root / name / "gt" / "gt.txt").write_text("\n".join([*GT_ROWS, FLAG0_ROW]) + "\n")
        (results / f"{name}.txt").write_text("\n".join(RESULT_ROWS) + "\n")
    return gt_root, results


def test_prints_the_table_and_writes_the_csv(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    gt_root, results = make_data(tmp_path)
    out = tmp_path / "scores.csv"
    assert eval_mot.main(["--results", str(results), "--gt-root", str(gt_root), "--out", str(out)]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].startswith("MOT15 scores by motmetrics") and "2 sequences" in printed[0]
    assert printed[2] == "| sequence | " + " | ".join(mot_metrics.COLUMNS) + " |"
    assert [line.split(" | ")[0] for line in printed[4:]] == ["| ADL-Rundle-6", "| KITTI-13", "| OVERALL"]
    assert printed[4].startswith("| ADL-Rundle-6 | 0.667 | 0.064 | 0.720 | 0.692 | 0.750 | 1 | 0.500 | 2 | 0 | 2 | 1 | 12 | 2 |")
    with out.open() as fh:
        rows = list(csv.DictReader(fh))
    assert [r["sequence"] for r in rows] == [*SEQUENCES, "OVERALL"]
    for row in rows[:2]:
        for name, value in EXPECTED.items():
            assert float(row[name]) == pytest.approx(value, rel=1e-5), name
    overall = rows[2]  # two copies of the case: counts doubled, ratios unchanged
    assert int(overall["num_objects"]) == 24 and int(overall["num_switches"]) == 2
    assert float(overall["mota"]) == pytest.approx(2 / 3, rel=1e-5)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary file left


def test_sequences_chooses_a_subset(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                    monkeypatch: pytest.MonkeyPatch) -> None:
    gt_root, results = make_data(tmp_path)
    (results / "ADL-Rundle-6.txt").unlink()  # its results are missing: fine when --sequences leaves it out
    monkeypatch.setenv("MOT_ROOT", str(gt_root))  # the default --gt-root
    assert eval_mot.main(["--results", str(results), "--sequences", "KITTI-13"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(" | ")[0] for line in lines[4:]] == ["| KITTI-13", "| OVERALL"]


def test_the_script_from_the_command_line(tmp_path: Path) -> None:
    gt_root, results = make_data(tmp_path, SEQUENCES[:1])
    done = run_script("eval_mot", "--results", str(results), "--gt-root", str(gt_root), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "| ADL-Rundle-6 | 0.667 |" in done.stdout and "| OVERALL | 0.667 |" in done.stdout


def _cases(data: Path) -> list:
    gt, res = data / "gt", data / "results"
    common = ("--results", str(res), "--gt-root", str(gt))
    return [
        misuse("--results", str(res), mentions="$MOT_ROOT"),  # no --gt-root and $MOT_ROOT unset
        misuse("--results", str(res), env={"MOT_ROOT": "{missing}"}, mentions="$MOT_ROOT"),
        misuse("--results", str(res), "--gt-root", "{dir}"),  # no <SEQ>/gt/gt.txt in it
        misuse(*common, "--sequences", "MOT17-02"), misuse(*common, "--sequences", "KITTI-13,KITTI-13"),
        misuse(*common, "--sequences", ""),
        misuse(*common, "--out", "{file}"), misuse(*common, "--out", "{under_file}"),
        misuse(*common, "--out", "{under_file}/scores.csv"), misuse(*common, "--out", "{dir}"),
        misuse(*common, "--out", "{dir}/" + "n" * 300),
    ]


@pytest.mark.parametrize("index", range(11))
def test_misuse(index: int, misuse_paths: MisusePaths, capsys: pytest.CaptureFixture[str],  # noqa: F811
                monkeypatch: pytest.MonkeyPatch) -> None:
    data = misuse_paths.root / "data"
    make_data(data)
    monkeypatch.delenv("MOT_ROOT", raising=False)
    cases = _cases(data)
    assert len(cases) == 11
    check_misuse(eval_mot.main, cases[index], misuse_paths, capsys, monkeypatch)


@pytest.mark.parametrize("problem", ["results_line", "gt_line", "unknown_results", "missing_results"])
def test_data_misuse_names_the_file(problem: str, misuse_paths: MisusePaths,  # noqa: F811
                                    capsys: pytest.CaptureFixture[str]) -> None:
    gt_root, results = make_data(misuse_paths.root / "data")
    if problem == "results_line":
        (results / "KITTI-13.txt").write_text("1,10,0,0,10,10,1,-1,-1,-1\n2,10,0,0,10\n")
        mentions = f"--results: {results / 'KITTI-13.txt'}:2: expected 10 comma-separated values"
    elif problem == "gt_line":
        (gt_root / "KITTI-13" / "gt" / "gt.txt").write_text("1,1,0,0,10,10,1,-1,-1,-1\n1,1,0,0,10,10,1,-1,-1,-1\n")
        mentions = f"--gt-root: {gt_root / 'KITTI-13' / 'gt' / 'gt.txt'}:2: repeats frame 1, id 1 of line 1"
    elif problem == "unknown_results":
        (results / "MOT17-02.txt").write_text("")
        mentions = f"--results: {results / 'MOT17-02.txt'} has no ground truth"
    else:
        (results / "KITTI-13.txt").unlink()
        mentions = "no results file for KITTI-13"
    case = misuse("--results", str(results), "--gt-root", str(gt_root), "--out", "{out}.csv", mentions=mentions)
    check_misuse(eval_mot.main, case, misuse_paths, capsys)
