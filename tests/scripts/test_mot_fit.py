"""scripts/mot_fit.py: the simulator's detection noise fitted to MOT15 (bboxtune.agents.commands.mot_fit), its outputs and
refusals; the committed docs/results/mot15_noise fit is what the command computes."""

from __future__ import annotations

import json
import os
import shlex
from pathlib import Path

import pytest

from bboxtune.agents.cli import key_values
from bboxtune.agents.commands import mot_fit
from bboxtune.envs.episodes.config import EnvConfig

from .cli_misuse import check_misuse, misuse

REPO = Path(__file__).resolve().parents[2]
MOT_ROOT = os.environ.get("MOT_ROOT")
needs_mot = pytest.mark.skipif(not MOT_ROOT, reason="MOT_ROOT is unset: the fit needs the MOT15 data "
                                                   "(CI: MOT_ROOT=../shared/data/mot15)")
COMMITTED = REPO / "docs" / "results" / "mot15_noise"


@needs_mot
def test_fit_on_the_mot15_data(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "fit"
    assert mot_fit.main(["--mot-root", str(MOT_ROOT), "--out", str(out), "--episodes", "60", "--seed", "5"]) == 0
    text = (out / "fit.md").read_text()
    assert text == capsys.readouterr().out
    assert "| statistic | MOT train | MOT val | MOT test | fitted sim |" in text
    assert "| identities (sim: episodes) | 51 | 134 | 15 | 60 |" in text
    assert "python scripts/mot_fit.py --mot-root" in text and "--episodes 60 --seed 5" in text
    kwargs = json.loads((out / "fitted_env_kwargs.json").read_text())
    assert (kwargs["source"], kwargs["sim_noise"], kwargs["detection_dropout"]) == ("sim", "box", "runs")
    assert kwargs["track_length"] == 173  # the train split's median identity length
    assert 0 <= kwargs["psi_range"][0] < kwargs["psi_range"][1] <= 0.95
    EnvConfig(**kwargs)
    # the train.py line gives the same env
    (line,) = [li for li in text.splitlines() if li.startswith("python scripts/train.py")]
    assert "--source sim --env-kwargs" in line
    items = line.split(" --env-kwargs ")[1]
    assert key_values("--env-kwargs", shlex.split(items)) == {k: v for k, v in kwargs.items() if k != "source"}
    assert (out / "fit.png").read_bytes().startswith(b"\x89PNG")
    # the committed fit: the same kwargs (they do not depend on --episodes or --seed)
    assert json.loads((COMMITTED / "fitted_env_kwargs.json").read_text()) == kwargs


@pytest.mark.parametrize("taken", mot_fit.OUTPUTS)
def test_refuses_an_output_folder_that_holds_its_files(taken: str, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / taken).write_text("mine")
    assert mot_fit.main(["--mot-root", str(tmp_path), "--out", str(tmp_path)]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert f"already holds {taken}" in line and (tmp_path / taken).read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == [taken]


def test_refuses_a_folder_without_mot_data(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert mot_fit.main(["--mot-root", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("error: ") and "sequences.csv" in line
    assert not (tmp_path / "o").exists()


def test_without_a_data_location_names_the_flag(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("MOT_ROOT", raising=False)
    assert mot_fit.main(["--out", str(tmp_path / "o")]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert "--mot-root" in line and "MOT_ROOT" in line and not (tmp_path / "o").exists()


CASES = [
    misuse(mentions="--out"),  # --out is required
    misuse("--out", "{under_file}"), misuse("--out", "{file}"), misuse("--out", ""),
    misuse("--out", "{out}", "--mot-root", "{missing}"), misuse("--out", "{out}", "--mot-root", "{file}"),
    *[misuse("--out", "{out}", "--episodes", v) for v in ("0", "-1", "abc", "1_0", "2.5", "10001")],
    *[misuse("--out", "{out}", "--seed", v) for v in ("-1", "abc", "nan")],
    misuse("--ou", "{out}", mentions="--ou"),  # flags are not abbreviated
]


@pytest.mark.parametrize("case", CASES, ids=str)
def test_misuse(case, misuse_paths, capsys, monkeypatch):  # noqa: F811  (the fixture)
    check_misuse(mot_fit.main, case, misuse_paths, capsys, monkeypatch)
