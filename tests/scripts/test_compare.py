"""scripts/compare.py on a tiny run with a few episodes: methods, columns, the episode choice of --seed / --split,
transfer with --env-kwargs, OTB enumeration with sequence clusters (the OTB cases need $OTB_ROOT)."""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np
import pytest

from bboxtune.agents.commands import compare as compare_command
from bboxtune.agents.policies.gate_file import read_gate
from bboxtune.agents.splits import eval_seeds, split_of, split_seeds

REQUIRED = ("method", "episode", "sequence", "tracker", "rmse", "success_auc", "precision20")
METHODS = {"raw", "bytetrack_kf", "sort_kf", "rule", "rule_est_sigma", "rule_true_sigma", "oracle", "oracle_auc", "global",
           "amortised", "adaptive", "ppo", "ppo_best"}
EPISODES = 6
FAST = ["--train-episodes", "24", "--global-trials", "8", "--oracle-budget", "16", "--bootstrap", "50"]
OTB = os.environ.get("OTB_ROOT")
needs_otb = pytest.mark.skipif(not OTB or not Path(OTB).is_dir(), reason="needs the OTB data ($OTB_ROOT)")


def compare(run: Path, out: Path, *args: str) -> Path:
    return compare_command.run(["--model", str(run), *FAST, "--out", str(out), *args])


def rows(out: Path) -> list[dict[str, str]]:
    with open(out / "results.csv") as fh:
        return list(csv.DictReader(fh))


def of(table: list[dict[str, str]], method: str, key: str) -> list[str]:
    return [r[key] for r in sorted((r for r in table if r["method"] == method), key=lambda r: int(r["episode"]))]


@pytest.fixture(scope="module")
def compared(tiny_run: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return compare(tiny_run, tmp_path_factory.mktemp("compare"), "--episodes", str(EPISODES))


def test_results_csv(compared: Path) -> None:
    table = rows(compared)
    assert tuple(table[0])[: len(REQUIRED)] == REQUIRED
    assert {r["method"] for r in table} == METHODS and len(table) == len(METHODS) * EPISODES
    assert {r["backend"] for r in table} == {"ufir_cmn"} and {(r["sequence"], r["tracker"]) for r in table} == {("", "")}
    assert of(table, "rule", "noise_seed") == [str(s) for s in eval_seeds("test", EPISODES)]  # seed 0: today's set
    by = {m: {int(r["episode"]): r for r in table if r["method"] == m} for m in METHODS}
    for e in range(EPISODES):
        rule = float(by["rule"][e]["rmse"])
        assert float(by["rule"][e]["log_ratio"]) == 0.0
        assert all(float(by[m][e]["rule_rmse"]) == rule for m in METHODS)
        assert float(by["oracle"][e]["rmse"]) <= min(rule, float(by["rule_true_sigma"][e]["rmse"]))
        assert float(by["oracle_auc"][e]["success_auc"]) >= float(by["rule"][e]["success_auc"])
        assert np.isfinite(float(by["ppo"][e]["rmse"])) and by["raw"][e]["param_psi"] == "nan"


def test_raw_is_the_unfiltered_measurement(compared: Path, tiny_run: Path) -> None:
    import gymnasium as gym

    from bboxtune.envs.episodes.scoring import score_estimates

    env = gym.make("bboxtune/FilterTune-v0", track_length=100, split="test")
    table = rows(compared)
    for e, seed in enumerate(eval_seeds("test", 2)):
        env.reset(options={"noise_seed": int(seed)})
        ep = env.unwrapped.episode
        expected = score_estimates(ep.y[None], ep.truth)
        assert float(of(table, "raw", "rmse")[e]) == pytest.approx(expected["rmse"][0], rel=1e-12)
        assert float(of(table, "raw", "success_auc")[e]) == pytest.approx(expected["success_auc"][0], rel=1e-12)


def test_summary_and_figures(compared: Path) -> None:
    text = (compared / "summary.md").read_text()
    for needle in ("## RMSE (px)", "IQM", "win rate vs rule", "regret vs oracle", "success AUC", "precision@20px",
                   "GT used at test", "## Paired: ppo against each method", "| oracle | y (truth) |", "| raw | n |",
                   "| oracle_auc | y (truth) |", "resamples of episodes (6 clusters: every episode its own)",
                   "(the run's own)",
                   # the tiny run's tracks all have 100 frames and no gap: these two inputs never varied in training
                   "- inputs held at their training value: ppo, ppo_best: frac_missing, log_n_frames"):
        assert needle in text, needle
    assert "Success AUC Δ vs raw by OTB attribute" not in text and "## Per tracker" not in text
    for name in ("gain_boxplot.png", "otb_curves.png", "trajectory.png"):
        assert (compared / name).stat().st_size > 1000


def test_seed_and_split_choose_the_episodes(tiny_run: Path, tmp_path: Path) -> None:
    first = rows(compare(tiny_run, tmp_path / "a", "--episodes", "3", "--seed", "4", "--split", "val"))
    again = rows(compare(tiny_run, tmp_path / "b", "--episodes", "3", "--seed", "4", "--split", "val"))
    seeds = of(first, "rule", "noise_seed")
    assert seeds == [str(s) for s in split_seeds("val", 3, 4)] and all(split_of(int(s)) == "val" for s in seeds)
    assert of(first, "ppo", "rmse") == of(again, "ppo", "rmse") and of(first, "global", "rmse") == of(again, "global", "rmse")
    train_split = rows(compare(tiny_run, tmp_path / "c", "--episodes", "2", "--split", "train", "--seed", "1"))
    assert of(train_split, "rule", "noise_seed") == [str(s) for s in split_seeds("train", 2, 1)]


def test_env_kwargs_change_the_evaluation_env(tiny_run: Path, tmp_path: Path) -> None:
    out = compare(tiny_run, tmp_path / "t", "--episodes", "2", "--env-kwargs", "track_length=40", "psi_range:[0.5, 0.6]")
    text = (out / "summary.md").read_text()
    assert "changed from the run's: ['psi_range', 'track_length']" in text
    psi = [float(p) for p in of(rows(out), "rule", "true_psi")]
    assert all(0.5 <= p <= 0.6 for p in psi)


@needs_otb
def test_otb_episodes_are_every_sequence_times_seeds_with_sequence_clusters(tiny_run: Path, tmp_path: Path) -> None:
    out = compare(tiny_run, tmp_path / "otb", "--env-kwargs", "source=otb", "--seeds-per-sequence", "2")
    table = rows(out)
    sequences = of(table, "rule", "sequence")
    assert len(sequences) == 2 * len(set(sequences)) and all(sequences.count(s) == 2 for s in sequences)
    assert len({*of(table, "rule", "noise_seed")}) == len(sequences) and set(of(table, "rule", "tracker")) == {""}
    assert "rule_true_sigma" not in {r["method"] for r in table}
    text = (out / "summary.md").read_text()
    n = len(set(sequences))
    assert f"resamples of sequences ({n} clusters; every drawn sequence brings all its episodes, {2 * n} in all)" in text
    for needle in ("## Success AUC and precision@20px against raw and the rule", "Success AUC Δ vs raw by OTB attribute",
                   "Success AUC Δ vs rule by OTB attribute", "| OCC (n=", f"{2 * n} = {n} test-split sequences × 2"):
        assert needle in text, needle


@needs_otb
def test_otb_tracker_episodes_are_every_sequence_times_every_tracker_with_output(tiny_run: Path, tmp_path: Path) -> None:
    out = compare(tiny_run, tmp_path / "trk", "--env-kwargs", "source=otb_tracker", "trackers=[MEEM, SiamFC]")
    table = rows(out)
    from bboxtune.envs.data.otb import OTBDataset, split

    data = OTBDataset(OTB)
    test = split(data.names)["test"]
    meem = set(data.tracker_sequences("MEEM"))  # MEEM lacks some sequences: clusters of 1 and 2 episodes
    expected = [(s, t) for s in test for t in ("MEEM", "SiamFC") if t == "SiamFC" or s in meem]
    assert list(zip(of(table, "rule", "sequence"), of(table, "rule", "tracker"), strict=False)) == expected
    assert len(expected) < 2 * len(test)
    text = (out / "summary.md").read_text()
    assert f"resamples of sequences ({len(test)} clusters; every drawn sequence brings all its episodes, " \
           f"{len(expected)} in all)" in text
    assert f"{len(expected)} = {len(test)} test-split sequences × 2 trackers" in text
    for needle in ("## Per tracker", "| MEEM | raw |", "| MEEM | ppo |", "| SiamFC | oracle |", "| SiamFC | oracle_auc |",
                   "| SiamFC | ppo_best |"):
        assert needle in text, needle
    assert "| MEEM | global |" not in text  # per tracker: raw, rule, the learned models and the oracles


@needs_otb
def test_mix_episodes_are_drawn_and_cluster_by_sequence_where_they_have_one(tiny_run: Path, tmp_path: Path) -> None:
    out = compare(tiny_run, tmp_path / "mix", "--env-kwargs", "source=mix", "--episodes", "8")
    table = rows(out)
    sources, sequences = of(table, "rule", "source"), of(table, "rule", "sequence")
    assert len(sources) == 8 and {"sim", "otb"} <= set(sources)
    assert all((s == "") == (src == "sim") for s, src in zip(sequences, sources, strict=False))
    lone, named = sources.count("sim"), len({s for s in sequences if s})
    assert f"({lone + named} clusters: {named} sequences, each with all its episodes, and {lone} episodes without a " \
           "sequence)" in (out / "summary.md").read_text()


def test_several_seeds_are_scored_together_and_aggregated(tiny_run: Path, train, tmp_path: Path, capsys) -> None:  # noqa: F811
    from .tiny_run import TINY

    second = train.run([*TINY, "--seed", "1", "--out", str(tmp_path / "s1")])
    out = compare_command.run(["--model", str(tiny_run), str(second), *FAST, "--episodes", "4", "--gate", "--val-episodes", "4",
                               "--out", str(tmp_path / "both")])
    table = rows(out)
    assert {"ppo_s0", "ppo_s1", "ppo_best_s0", "ppo_best_s1", "ppo_gated_s0", "ppo_gated_s1", "rule", "oracle"} <= \
        {r["method"] for r in table}
    assert of(table, "ppo_s0", "episode") == of(table, "ppo_s1", "episode") == ["0", "1", "2", "3"]  # the same episodes
    summary = (out / "summary.md").read_text()
    section = summary.split("## Across training seeds")[1]
    assert "| ppo | 2 |" in section and "| ppo_best | 2 |" in section and "| rule | 1 | +0.000 [+0.000, +0.000]" in section
    assert "| ppo_gated | 2 |" in section
    assert (out / "performance_profile.png").stat().st_size > 0
    for argv, match in ((["--model", str(tiny_run), str(second)], "--out: required with several --model"),
                        (["--model", str(tiny_run), str(tiny_run), "--out", str(tmp_path / "x")], "seed 0 again")):
        capsys.readouterr()
        with pytest.raises(SystemExit) as exit_info:
            compare_command.main(argv)
        assert exit_info.value.code == 2 and match in capsys.readouterr().err


def test_gate_uses_the_model_or_leaves_the_measurements_alone(tiny_run: Path, tmp_path: Path) -> None:
    """--gate: per episode, ppo_gated scores either exactly as ppo (its parameters) or exactly as raw (the
    measurements, no parameters); the summary names the gate's fit and the chosen margin. --gate is refused for a run
    it does not apply to (FilterRetune-v0: tests/scripts/test_compare_retune.py)."""
    out = compare(tiny_run, tmp_path / "gate", "--episodes", str(EPISODES), "--gate", "--val-episodes", "5")
    table = rows(out)
    ppo, raw, gated = ({int(r["episode"]): r for r in table if r["method"] == m} for m in ("ppo", "raw", "ppo_gated"))
    keys = ("param_psi", "param_horizon", "rmse", "success_auc", "precision20")
    assert len(gated) == EPISODES
    assert all([row[k] for k in keys] in ([ppo[e][k] for k in keys], [raw[e][k] for k in keys]) for e, row in gated.items())
    summary = (out / "summary.md").read_text()
    assert "- gate (--gate): the run's own env" in summary and "24 train-split episodes" in summary
    assert "5 val-split episodes; ppo_gated margin" in summary and "## Paired: ppo_gated against each method" in summary
    margin = read_gate(out / "gates" / "ppo_gated.json", 21).margin  # the fitted gate (msd features), for smooth.py --gate
    assert f"ppo_gated margin {margin:+.3g} (" in summary
