"""The simulated results rows (docs/results-sim.md) come from the runs committed under docs/results/<backend>/run/.

The fast tests load each committed run without pickles and check its spaces; the slow test re-runs
``scripts/compare.py --model docs/results/<backend>/run --episodes 500`` and checks that the tables of its
summary.md equal the published docs/results/<backend>/summary.md (less the rows of methods added since: raw,
oracle_auc) and that every number of the page's rows for that back end is in the new summary (a few minutes
per back end on 2 cores)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from bboxtune.agents.commands import compare
from bboxtune.agents.training.runs import SB3Policy, load_config, make_env

ROOT = Path(__file__).resolve().parents[2]
BACKENDS = ("ufir_cmn", "kf_cmn")
# results row label (start of the second column) -> method name in summary.md
LABELS = {"rule with σ estimated": "rule_est_sigma", "rule_est_sigma": "rule_est_sigma", "rule with true": "rule_true_sigma",
          "rule": "rule", "global": "global", "adaptive": "adaptive", "amortised": "amortised", "**PPO": "ppo",
          "oracle": "oracle"}


def run_dir(backend: str) -> Path:
    return ROOT / "docs" / "results" / backend / "run"


@pytest.mark.parametrize(("folder", "features"), [*((b, "base") for b in BACKENDS), *((f"msd_{b}", "msd") for b in BACKENDS)])
def test_committed_run_loads_without_pickles(folder: str, features: str) -> None:
    """The base-feature runs of the first table and seed 0 of the msd feature set's runs (docs/results/msd_<backend>)."""
    run = run_dir(folder)
    assert not list(run.glob("*.pkl")), "a published run must not need a pickle"
    cfg = load_config(run)
    assert cfg["env_kwargs"]["backend"] == folder.removeprefix("msd_")
    assert cfg["env_kwargs"].get("features", "base") == features
    env = make_env(cfg["env_id"], cfg["env_kwargs"])
    assert env.observation_space.shape == ((21,) if features == "msd" else (20,))
    obs, _ = env.reset(seed=0)
    for which in ("final", "best"):
        policy = SB3Policy.load(run, which)  # refuses pickles and checks the spaces against config.yml
        action = policy.predict(obs[None])[0]
        assert env.action_space.contains(action.astype(env.action_space.dtype))


ADDED = ("raw", "oracle_auc")  # methods compare.py has scored since the runs were published (issue 11)


def _tables(summary: str) -> list[str]:
    """The table lines of a summary, without the rows of the methods added since publication."""
    return [line for line in summary.splitlines() if line.startswith("|") and line.split("|")[1].strip() not in ADDED]


def _readme_rows(backend: str) -> list[tuple[str, list[str]]]:
    rows = []
    for line in (ROOT / "docs" / "results-sim.md").read_text().splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) == 8 and cells[0] == backend:
            method = next(m for label, m in LABELS.items() if cells[1].startswith(label))
            rows.append((method, [c.strip("*") for c in cells[3:]]))
    return rows


@pytest.mark.slow
@pytest.mark.parametrize("backend", BACKENDS)
def test_readme_rows_are_reproduced_from_the_committed_run(backend: str, tmp_path: Path) -> None:
    out = tmp_path / "compare"
    compare.run(["--model", str(run_dir(backend)), "--episodes", "500", "--out", str(out)])
    summary = (out / "summary.md").read_text()
    assert _tables(summary) == _tables((ROOT / "docs" / "results" / backend / "summary.md").read_text())
    rows = [(line.split("|")[1].strip(), line) for line in _tables(summary)]
    readme = _readme_rows(backend)
    assert len(readme) >= 7
    for method, numbers in readme:
        for number in numbers:
            if number in ("0", "1", "–"):
                continue
            value = re.sub(r"\s", " ", number).replace("−", "-")
            found = [line for name, line in rows if name == method and _numbers_in(value, line)]
            assert found, f"docs/results-sim.md {backend} {method}: {number!r} not in the new summary.md"


def _numbers_in(value: str, line: str) -> bool:
    """Every number of ``value`` (the page's rounding) is, rounded alike, among the numbers of ``line``."""
    table = re.findall(r"[-+]?[0-9]+\.[0-9]+", line)
    for number in re.findall(r"[-+]?[0-9]+\.[0-9]+", value):
        digits = len(number.split(".")[1])
        if not any(abs(float(t) - float(number)) <= 0.5 * 10**-digits + 1e-12 for t in table):
            return False
    return True
