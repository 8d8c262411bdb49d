"""YAML hyperparameters in the RL Zoo layout: parsed without eval here, and loaded as is by the zoo's own CLI."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import torch.nn as nn
import yaml
from stable_baselines3.common.noise import NormalActionNoise

from bboxtune.agents.training.algos import ALGOS
from bboxtune.agents.training.hyperparams import FILE_KEYS, HYPERPARAMS_DIR, constructor_kwargs, load_hyperparams, parse_schedule
from bboxtune.envs import ENV_IDS
from bboxtune.envs.vector import BATCHED_IDS

from ..conftest import ENV_ID

REPO = Path(__file__).resolve().parents[3]
FILES = sorted(HYPERPARAMS_DIR.glob("*.yml"))
# every (algo, env id) entry the shipped files hold for a registered env
ZOO_CASES = [(p.stem, env_id) for p in FILES for env_id in ENV_IDS if env_id in yaml.safe_load(p.read_text())]
# settings that shrink a zoo run to seconds (small rollouts, early updates); the file's other values stay
TINY: dict[str, dict[str, int]] = {
    "ppo": {"n_envs": 2, "n_steps": 16, "batch_size": 32},
    "a2c": {"n_envs": 2, "n_steps": 16},
    "sac": {"learning_starts": 16, "batch_size": 16},
    "td3": {"learning_starts": 16, "batch_size": 16},
    "ppo_lstm": {"n_envs": 2, "n_steps": 16, "batch_size": 32},
}
ENTRY = "  n_timesteps: 1000\n  policy: MlpPolicy\n"  # the keys every entry needs


class _ZooConfigLoader(yaml.SafeLoader):
    """Reads the zoo's saved ``config.yml`` (an OrderedDict dumped with its Python tag) into a plain dict; a
    ``!!python/name:`` tag (a class SB3 put into ``policy_kwargs``) becomes its name, nothing is imported."""


_ZooConfigLoader.add_constructor(
    "tag:yaml.org,2002:python/object/apply:collections.OrderedDict",
    lambda loader, node: dict(loader.construct_sequence(node, deep=True)[0]))
_ZooConfigLoader.add_multi_constructor("tag:yaml.org,2002:python/name:", lambda loader, suffix, node: suffix)


def test_one_file_per_algo() -> None:
    assert [p.stem for p in FILES] == sorted(ALGOS)


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_every_entry_of_every_file_loads(path: Path) -> None:
    data = yaml.safe_load(path.read_text())
    entries = [key for key, value in data.items() if isinstance(value, dict)]
    assert "default" in entries and ENV_ID in entries
    for key in entries:
        hp = load_hyperparams(path.stem, key)
        batched = data["vec_env"] == "batched" and key not in BATCHED_IDS  # the file's batched means subproc here
        assert hp.n_timesteps > 0 and hp.n_envs >= 1 and hp.vec_env == ("subproc" if batched else data["vec_env"])
        assert hp.policy == ("MlpLstmPolicy" if path.stem == "ppo_lstm" else "MlpPolicy")
        assert hp.normalize == {"norm_obs": True, "norm_reward": False}


def test_linear_schedule() -> None:
    sched = parse_schedule("lin_3e-4", where="test")
    assert sched(1.0) == pytest.approx(3e-4) and sched(0.5) == pytest.approx(1.5e-4) and sched(0.0) == 0.0
    assert parse_schedule(1e-3, where="test") == 1e-3
    with pytest.raises(ValueError, match="lin_"):
        parse_schedule("exp_1e-3", where="test")


def test_entry_used_as_is_default_for_other_ids(tmp_path: Path) -> None:
    """As in the zoo: an env id's entry is not merged with ``default``; YAML merge keys share settings."""
    (tmp_path / "ppo.yml").write_text(
        "vec_env: subproc\n"
        f"default: &d\n{ENTRY}  n_steps: 64\n  learning_rate: lin_1e-3\n"
        "my/Env-v0:\n  <<: *d\n  n_steps: 32\n"
        f"bare/Env-v0:\n{ENTRY}")
    hp = load_hyperparams("ppo", "my/Env-v0", directory=tmp_path)
    assert hp.algo_kwargs["n_steps"] == 32 and hp.algo_kwargs["learning_rate"](1.0) == pytest.approx(1e-3)
    assert hp.vec_env == "subproc" and hp.raw["vec_env"] == "subproc"
    assert load_hyperparams("ppo", "bare/Env-v0", directory=tmp_path).algo_kwargs == {}
    other = load_hyperparams("ppo", "other/Env-v0", {"n_steps": 16, "vec_env": "dummy"}, directory=tmp_path)
    assert other.algo_kwargs["n_steps"] == 16 and other.vec_env == "dummy"


def test_vec_env_defaults_to_dummy(tmp_path: Path) -> None:
    (tmp_path / "ppo.yml").write_text(f"default:\n{ENTRY}")
    assert load_hyperparams("ppo", "my/Env-v0", directory=tmp_path).vec_env == "dummy"


def test_activation_fn_override(tmp_path: Path) -> None:
    (tmp_path / "ppo.yml").write_text(f"default:\n{ENTRY}  policy_kwargs: {{net_arch: [8]}}\n")
    hp = load_hyperparams("ppo", "my/Env-v0", {"policy_kwargs": {"net_arch": [8], "activation_fn": "relu"}},
                          directory=tmp_path)
    assert hp.algo_kwargs["policy_kwargs"] == {"net_arch": [8], "activation_fn": nn.ReLU}
    with pytest.raises(ValueError, match="activation_fn='swish'"):
        load_hyperparams("ppo", "my/Env-v0", {"policy_kwargs": {"activation_fn": "swish"}}, directory=tmp_path)


@pytest.mark.parametrize("text, match", [
    (f"default:\n{ENTRY}  not_a_kwarg: 1\n", "not accepted"),
    (f"default:\n{ENTRY}  policy_kwargs: \"dict(net_arch=[64])\"\n", "mapping"),  # the zoo would eval it
    (f"default:\n{ENTRY}  normalize: \"dict(norm_obs=True)\"\n", "normalize"),  # the zoo would eval it
    (f"default:\n{ENTRY}  policy_kwargs: {{activation_fn: relu}}\n", "activation_fn in a file"),
    (f"vec_env: threads\ndefault:\n{ENTRY}", "vec_env='threads'"),
    (f"default:\n{ENTRY}  vec_env: dummy\n", "vec_env inside an entry"),
    ("default:\n  policy: MlpPolicy\n", r"\['n_timesteps'\] missing"),
    ("default:\n  n_timesteps: 1000\n", r"\['policy'\] missing"),
    (f"default:\n{ENTRY}my/Env-v0:\n  n_steps: 32\n", r"\[my/Env-v0\]: \['n_timesteps', 'policy'\] missing"),
    (f"n_envs: 2\ndefault:\n{ENTRY}", r"top-level \['n_envs'\]"),
    (f"other/Env-v0:\n{ENTRY}", "default"),
    ("- default\n", "expected a mapping"),
])
def test_bad_entries_raise(tmp_path: Path, text: str, match: str) -> None:
    (tmp_path / "ppo.yml").write_text(text)
    with pytest.raises(ValueError, match=match):
        load_hyperparams("ppo", "my/Env-v0", directory=tmp_path)


def test_td3_action_noise_built_for_the_action_size() -> None:
    kwargs = constructor_kwargs(load_hyperparams("td3", ENV_ID), action_dim=3)
    assert isinstance(kwargs["action_noise"], NormalActionNoise) and kwargs["action_noise"]().shape == (3,)


def _monitor_steps(run: Path) -> int:
    """Env steps of the finished episodes in the zoo's ``*.monitor.csv`` files (a comment, ``r,l,t``, rows)."""
    rows = [line for f in run.glob("*.monitor.csv") for line in f.read_text().splitlines()[2:]]
    return sum(int(row.split(",")[1]) for row in rows)


@pytest.mark.parametrize("algo, env_id", ZOO_CASES)
def test_file_trains_in_the_rl_zoo_as_is(algo: str, env_id: str, tmp_path: Path) -> None:
    """``python -m rl_zoo3.train -conf agents/hyperparams/<algo>.yml``: a 64-step run on 100-frame tracks; the
    hyperparameters the zoo saved are the ones bboxtune.agents.training.hyperparams reads (with the same overrides)."""
    overrides: dict[str, Any] = TINY[algo]
    command = [sys.executable, "-m", "rl_zoo3.train", "--algo", algo, "--env", env_id, "--gym-packages", "bboxtune",
               "-conf", str(HYPERPARAMS_DIR / f"{algo}.yml"), "-n", "64", "-f", str(tmp_path), "--seed", "0",
               "--verbose", "0", "--num-threads", "1", "--eval-freq", "32", "--eval-episodes", "2",
               "--env-kwargs", "track_length:100", "-params", *(f"{k}:{v}" for k, v in overrides.items())]
    done = subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=600)  # only to catch a hang
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-4000:]
    name = env_id.replace("/", "-")
    run = tmp_path / algo / f"{name}_1"
    used = yaml.load((run / name / "config.yml").read_text(), Loader=_ZooConfigLoader)
    ours = {key: value for key, value in load_hyperparams(algo, env_id, overrides).raw.items() if key not in FILE_KEYS}
    assert used.keys() == ours.keys()
    for key, value in ours.items():
        # the zoo saves the mappings it and SB3 filled in place (VecNormalize's gamma, use_sde, optimizer_class)
        assert ({k: used[key][k] for k in value} if isinstance(value, dict) else used[key]) == value, key
    assert _monitor_steps(run) >= 64 and (run / f"{name}.zip").is_file()
