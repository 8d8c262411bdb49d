"""scripts/compare.py on tiny FilterRetune-v0 runs (scenario "nonstationary"; two training seeds): the re-tuning
methods, one row per method × episode (window_amortised fitted twice with --fit-seeds 2), the gap table, the
across-seeds table, the parameter-schedule figure, and --oneshot-model's checks."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from bboxtune.agents.commands import compare

from .tiny_run import TINY

METHODS = {"raw", "rule", "oneshot_oracle", "oneshot_learned", "oneshot_learned_online", "window_oracle", "adaptive", "imm",
           "ppo_s0", "ppo_s1", "ppo_best_s0", "ppo_best_s1", "window_amortised_s0", "window_amortised_s1",
           "window_anchored_s0", "window_anchored_s1", "window_residual_s0", "window_residual_s1"}
EPISODES = 4
NONSTATIONARY = ["--env-kwargs", "track_length:100", "scenario:nonstationary"]


def _tiny(*extra: str) -> list[str]:
    i = TINY.index("--env-kwargs")
    return [*TINY[:i], *TINY[i + 2:], *NONSTATIONARY, *extra]


@pytest.fixture(scope="module")
def runs(train, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:  # noqa: F811
    root = tmp_path_factory.mktemp("retune_runs")
    retune = [train.run([*_tiny("--env", "bboxtune/FilterRetune-v0", "--env-kwargs", "window:40"), "--seed", str(seed),
                         "--out", str(root / f"rt{seed}")]) for seed in (0, 1)]
    oneshot = train.run([*_tiny(), "--out", str(root / "os")])
    return retune[0], oneshot, retune[1]


def test_compare_scores_retune_runs_against_every_baseline(runs: tuple[Path, Path, Path], tmp_path: Path) -> None:
    retune, oneshot, second = runs
    out = compare.run(["--model", str(retune), str(second), "--oneshot-model", str(oneshot), "--episodes",
                       str(EPISODES), "--oracle-budget", "16", "--bootstrap", "50", "--train-episodes", "12", "--fit-seeds", "2",
                       "--val-episodes", "2", "--out", str(tmp_path / "c")])
    with open(out / "results.csv") as fh:
        table = list(csv.DictReader(fh))
    assert {r["method"] for r in table} == METHODS and len(table) == len(METHODS) * EPISODES
    assert {r["scored_from"] for r in table} == {"40"}
    for e in range(EPISODES):
        by = {r["method"]: r for r in table if int(r["episode"]) == e}
        assert float(by["rule"]["log_ratio"]) == 0.0
        assert float(by["oneshot_oracle"]["rmse"]) <= float(by["rule"]["rmse"]) + 1e-9
    summary = (out / "summary.md").read_text()
    assert "## Re-tuning: the one-shot → per-window gap" in summary and "Paired: sequential against oneshot_learned" in summary
    assert "| window_amortised_s1 |" in summary.split("Paired: sequential against oneshot_learned")[1]
    assert "| window_anchored_s1 |" in summary.split("Paired: sequential against oneshot_learned")[1]
    assert "| window_residual_s1 |" in summary.split("Paired: sequential against oneshot_learned")[1]
    assert "margin chosen on 2 val-split episodes: window_anchored_s0 " in summary
    assert "moved by 24 offsets (5 per dimension in ±0.25" in summary  # ufir_cmn: 2 action dimensions
    assert "val-split episodes: window_residual_s0 " in summary
    assert "oneshot_learned: `" in summary and (out / "parameter_schedule.png").stat().st_size > 0
    seeds = summary.split("## Across training seeds")[1].split("## Figures")[0]
    for row in ("| ppo | 2 |", "| ppo_best | 2 |", "| window_amortised | 2 |", "| window_anchored | 2 |",
                "| window_residual | 2 |", "| rule | 1 | +0.000 [+0.000, +0.000]",
                "| oneshot_learned | 1 |", "| window_oracle | 1 |"):
        assert row in seeds


def test_oneshot_model_must_be_a_one_step_run(runs: tuple[Path, Path, Path], tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    retune, *_ = runs
    with pytest.raises(SystemExit) as exc:
        compare.run(["--model", str(retune), "--oneshot-model", str(retune), "--out", str(tmp_path / "c")])
    assert exc.value.code == 2
    assert "--oneshot-model" in capsys.readouterr().err and not (tmp_path / "c").exists()


@pytest.mark.parametrize(("flags", "with_oneshot", "message"), [
    (["--anchor-margin", "0.1"], False, "--anchor-margin: only with --oneshot-model"),
    (["--val-episodes", "5"], False, "--val-episodes: only with --oneshot-model"),
    (["--val-episodes", "5", "--anchor-margin", "0.1"], True, "--val-episodes: not used with --anchor-margin"),
    (["--anchor-margin", "-0.1"], True, "invalid value '-0.1'; allowed: finite numbers >= 0"),
    (["--anchor-margin", "nan"], True, "invalid value 'nan'"),
    (["--val-episodes", "0"], True, "--val-episodes"),
    (["--gate"], False, "--gate: only for runs of bboxtune/FilterTune-v0"),
])
def test_anchor_flags_are_checked_before_any_work(runs: tuple[Path, Path, Path], tmp_path: Path, flags: list[str],
                                                  with_oneshot: bool, message: str, capsys: pytest.CaptureFixture[str]) -> None:
    retune, oneshot, _ = runs
    extra = ["--oneshot-model", str(oneshot)] if with_oneshot else []
    with pytest.raises(SystemExit) as exc:
        compare.run(["--model", str(retune), *extra, *flags, "--out", str(tmp_path / "c")])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err and not (tmp_path / "c").exists()


def test_an_offline_view_run_is_scored_and_a_causal_model_is_refused_there(
        train, runs: tuple[Path, Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:  # noqa: F811
    """retune_view=offline travels with the run (config.yml): the sequential model and the window regressor it fits
    observe the offline view; a causal model asked on it is refused (observation shape), nothing written."""
    causal, oneshot, _ = runs
    offline = train.run([*_tiny("--env", "bboxtune/FilterRetune-v0", "--env-kwargs", "window:40", "retune_view:offline"),
                         "--out", str(tmp_path / "off")])
    out = compare.run(["--model", str(offline), "--oneshot-model", str(oneshot), "--episodes", "2", "--oracle-budget", "16",
                       "--bootstrap", "50", "--train-episodes", "11", "--anchor-margin", "1e9", "--out", str(tmp_path / "c")])
    with open(out / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert {"ppo", "window_amortised", "window_anchored", "window_residual", "oneshot_learned"} <= {r["method"] for r in rows}
    rmse = {(r["method"], r["episode"]): r["rmse"] for r in rows}
    for e in ("0", "1"):  # a margin no prediction exceeds: the one-shot tuner's action in every window
        assert rmse["window_anchored", e] == rmse["window_residual", e] == rmse["oneshot_learned", e]
    summary = (out / "summary.md").read_text()
    assert "'retune_view': 'offline'" in summary and "margin (--anchor-margin): window_anchored 1e+09" in summary
    assert "margin (--anchor-margin): window_residual 1e+09" in summary
    with pytest.raises(SystemExit) as exc:
        compare.run(["--model", str(causal), "--env-kwargs", "retune_view:offline", "--episodes", "2",
                     "--out", str(tmp_path / "refused")])
    assert exc.value.code == 2
    assert "observation" in capsys.readouterr().err and not (tmp_path / "refused").exists()


def test_without_model_the_baselines_regressors_and_the_regime_informed_reference_are_scored(tmp_path: Path) -> None:
    """No --model: --env bboxtune/FilterRetune-v0 and --env-kwargs give the env; every method but a trained tuner
    is scored, and --regime-informed adds the regressor told the true schedule, with its own across-seeds group, and
    the best action per true regime state."""
    out = compare.run(["--env", "bboxtune/FilterRetune-v0", *NONSTATIONARY, "window:20", "--episodes", "3",
                       "--oracle-budget", "16", "--bootstrap", "50", "--train-episodes", "11", "--fit-seeds", "2",
                       "--regime-informed", "--out", str(tmp_path / "c")])
    with open(out / "results.csv") as fh:
        table = list(csv.DictReader(fh))
    assert {r["method"] for r in table} == {"raw", "rule", "oneshot_oracle", "window_oracle", "regime_oracle", "adaptive", "imm",
                                            "window_amortised_s0", "window_amortised_s1",
                                            "window_regime_informed_s0", "window_regime_informed_s1"}
    assert {r["scored_from"] for r in table} == {"20"}
    summary = (out / "summary.md").read_text()
    assert "- model: none (no --model" in summary and "window tuners vs baselines" in summary
    assert "| window_regime_informed_s0 | regimes (truth) |" in summary
    assert "| regime_oracle | y (truth, per regime state) |" in summary and "- regime_oracle: in every window" in summary
    assert "- window_amortised: window_amortised_s0, window_amortised_s1: per-window" in summary
    seeds = summary.split("## Across training seeds")[1].split("## Figures")[0]
    assert "| window_amortised | 2 |" in seeds and "| window_regime_informed | 2 |" in seeds
