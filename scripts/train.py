#!/usr/bin/env python
"""Train a filter tuner (stable-baselines3) on a bboxtune env and write a run directory.

    python scripts/train.py                      # PPO, bboxtune/FilterTune-v0, sim source, ufir_cmn back end
    python scripts/train.py --backend kf_cmn --seed 1
    python scripts/train.py --resume runs/ppo_ufir_cmn_sim_s0   # continue a killed run

Episodes: training draws the train split, the EvalCallback scores the val split (``agents.splits``: disjoint
noise-seed sets; OTB sources also use the env's sequence splits). Observations are normalised by
VecNormalize (obs only; the reward log(RMSE_rule/RMSE) is already scale-free). The run directory layout is in
``agents.runs``. Same seed → same result on the same machine (uninterrupted runs); a resumed run continues from
its last checkpoint with reseeded envs (seed + timesteps done), so it does not replay earlier episodes.
"""

from __future__ import annotations

import argparse
import platform
import shlex
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

import gymnasium  # noqa: E402
import numpy as np  # noqa: E402
import stable_baselines3  # noqa: E402
import torch  # noqa: E402
import yaml  # noqa: E402
from stable_baselines3.common.callbacks import CallbackList, EvalCallback  # noqa: E402
from stable_baselines3.common.vec_env import VecNormalize  # noqa: E402

import envs  # noqa: E402,F401
import filters  # noqa: E402
from agents.algos import ALGOS, algo_class  # noqa: E402
from envs.config import SOURCES  # noqa: E402
from agents.callbacks import AtomicCheckpoint, EpisodeLog, SaveBestNormalizer, restore_eval_state  # noqa: E402
from agents.hyperparams import constructor_kwargs, load_hyperparams  # noqa: E402
from agents.plots import learning_curve  # noqa: E402
from agents.runs import HelpFormatter, latest_checkpoint, load_config, make_vec, write_text_atomic  # noqa: E402

DEFAULT_ENV = "bboxtune/FilterTune-v0"


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=HelpFormatter)
    p.add_argument("--algo", default="ppo", choices=sorted(ALGOS), help="SB3 algorithm")
    p.add_argument("--env", default=DEFAULT_ENV, help="env id (registered by `import envs`)")
    p.add_argument("--backend", default="ufir_cmn", choices=filters.NAMES, help="filter back end the tuner sets")
    p.add_argument("--source", default="sim", choices=SOURCES, help="episode source (video: set --env-kwargs detector:NAME)")
    p.add_argument("--reward", default="rmse", choices=("rmse", "iou_precision", "success_auc"), help="env reward")
    p.add_argument("--timesteps", type=int, default=None,
                   help="total env steps (one step = one episode for FilterTune-v0); default: n_timesteps of "
                        "agents/hyperparams/<algo>.yml; with --resume: the run's own total")
    p.add_argument("--seed", type=int, default=0, help="seed of the model, the envs and the train split")
    p.add_argument("--n-envs", type=int, default=None, help="parallel training envs (default: the YAML's n_envs)")
    p.add_argument("--out", type=Path, default=None, help="run directory (default runs/<algo>_<backend>_<source>_s<seed>)")
    p.add_argument("--resume", type=Path, default=None, metavar="DIR",
                   help="continue the run in DIR from its last checkpoint (its settings come from DIR/config.yml)")
    p.add_argument("--tensorboard", action="store_true", help="also log to DIR/tensorboard (needs the tensorboard package)")
    p.add_argument("--eval-freq", type=int, default=10_000, help="timesteps between evaluations on the val split")
    p.add_argument("--eval-episodes", type=int, default=200, help="val episodes per evaluation (the same ones each time)")
    p.add_argument("--checkpoint-freq", type=int, default=20_000, help="timesteps between checkpoints")
    p.add_argument("--hyperparams", nargs="*", default=[], metavar="KEY:VALUE",
                   help="override entries of agents/hyperparams/<algo>.yml (YAML values), e.g. n_steps:64 learning_rate:lin_1e-3")
    p.add_argument("--env-kwargs", nargs="*", default=[], metavar="KEY:VALUE",
                   help="more env arguments (envs.config.EnvConfig fields, YAML values), e.g. track_length:200")
    args = p.parse_args(argv)
    args.hyperparams = _key_values(p, "--hyperparams", args.hyperparams)
    args.env_kwargs = _key_values(p, "--env-kwargs", args.env_kwargs)
    clash = sorted(set(args.env_kwargs) & {"backend", "source", "reward", "split"})
    if clash:
        p.error(f"--env-kwargs {clash}: use --backend/--source/--reward (the split is set per use)")
    for name in ("timesteps", "n_envs", "eval_freq", "eval_episodes", "checkpoint_freq"):
        value = getattr(args, name)
        if value is not None and value < 1:
            p.error(f"--{name.replace('_', '-')}={value}: allowed integers >= 1")
    return args


def _key_values(p: argparse.ArgumentParser, flag: str, items: list[str]) -> dict[str, Any]:
    out = {}
    for item in items:
        key, sep, value = item.partition(":")
        if not sep or not key:
            p.error(f"{flag} {item!r}: expected KEY:VALUE")
        out[key] = yaml.safe_load(value)
    return out


def new_config(args: argparse.Namespace) -> dict[str, Any]:
    overrides = {**args.hyperparams, **({"n_envs": args.n_envs} if args.n_envs else {})}
    hp = load_hyperparams(args.algo, args.env, overrides)
    return {
        "algo": args.algo, "env_id": args.env, "seed": args.seed,
        "env_kwargs": {"backend": args.backend, "source": args.source, "reward": args.reward, **args.env_kwargs},
        "total_timesteps": args.timesteps or hp.n_timesteps,
        "eval_freq": args.eval_freq, "eval_episodes": args.eval_episodes, "checkpoint_freq": args.checkpoint_freq,
        "tensorboard": args.tensorboard, "hyperparams": hp.raw,
        "splits": "train: noise seeds drawn outside [1e9, 3e9); val: 2e9 + i; test: 1e9 + i (agents/splits.py)",
        "versions": {"python": platform.python_version(), "stable_baselines3": stable_baselines3.__version__,
                     "torch": str(torch.__version__), "gymnasium": gymnasium.__version__, "numpy": np.__version__},
        "created": time.strftime("%Y-%m-%d %H:%M:%S"),
    }


def build(cfg: dict[str, Any], run_dir: Path, checkpoint: Path | None):
    """The model (new or loaded from ``checkpoint``), its training VecEnv and the callbacks."""
    hp = load_hyperparams(cfg["algo"], cfg["env_id"], cfg["hyperparams"])
    done = 0
    state: dict[str, Any] = {}
    if checkpoint is not None:
        import json

        state = json.loads((checkpoint / "state.json").read_text())
        done = int(state["num_timesteps"])
    seed = int(cfg["seed"]) + done  # resumed envs do not replay the first segment's episodes
    venv = make_vec(cfg["env_id"], cfg["env_kwargs"], split="train", n_envs=hp.n_envs, seed=seed, vec_env=hp.vec_env)
    eval_env = make_vec(cfg["env_id"], cfg["env_kwargs"], split="val", n_envs=1, seed=int(cfg["seed"]),
                        cycle=cfg["eval_episodes"])
    tb = str(run_dir / "tensorboard") if cfg["tensorboard"] else None
    cls = algo_class(cfg["algo"])
    if checkpoint is None:
        if hp.normalize:
            venv = VecNormalize(venv, **hp.normalize)
        model = cls(hp.policy, venv, seed=int(cfg["seed"]), device="cpu", verbose=0, tensorboard_log=tb,
                    **constructor_kwargs(hp, venv.action_space.shape[0]))
    else:
        if (checkpoint / "vecnormalize.pkl").exists():
            venv = VecNormalize.load(str(checkpoint / "vecnormalize.pkl"), venv)
            venv.training = True
        model = cls.load(checkpoint / "model.zip", env=venv, device="cpu", tensorboard_log=tb)
        model.set_random_seed(seed)
        model._last_obs = None  # the fresh envs have no episode yet: make learn() reset them
        if (checkpoint / "replay_buffer.pkl").exists():
            model.load_replay_buffer(checkpoint / "replay_buffer.pkl")
    if hp.normalize:
        eval_env = VecNormalize(eval_env, training=False, norm_obs=hp.normalize.get("norm_obs", True), norm_reward=False)
    episode_log = EpisodeLog(state.get("episode_timesteps"), state.get("episode_rewards"))
    evaluation = EvalCallback(eval_env, eval_freq=max(cfg["eval_freq"] // hp.n_envs, 1),
                              n_eval_episodes=cfg["eval_episodes"], deterministic=True, log_path=str(run_dir),
                              best_model_save_path=str(run_dir), verbose=0,
                              callback_on_new_best=SaveBestNormalizer(run_dir / "best_vecnormalize.pkl"))
    restore_eval_state(evaluation, state)
    checkpointer = AtomicCheckpoint(run_dir, cfg["checkpoint_freq"], episode_log, evaluation)
    return model, CallbackList([episode_log, evaluation, checkpointer]), episode_log, evaluation, checkpointer


def main(argv: list[str] | None = None) -> Path:
    args = parse_args(argv)
    command = shlex.join([Path(sys.executable).name, *sys.argv]) if argv is None else shlex.join(["train.py", *argv])
    if args.resume is not None:
        run_dir = args.resume
        cfg = load_config(run_dir)
        if args.timesteps:
            cfg["total_timesteps"] = args.timesteps
        checkpoint = latest_checkpoint(run_dir)
        if checkpoint is None:
            raise SystemExit(f"{run_dir} has no checkpoint to resume from; start it again without --resume")
        with open(run_dir / "command.txt", "a") as fh:
            fh.write(command + "\n")
    else:
        cfg = new_config(args)
        run_dir = args.out or Path("runs") / f"{args.algo}_{args.backend}_{args.source}_s{args.seed}"
        if run_dir.exists() and any(run_dir.iterdir()):
            raise SystemExit(f"--out {run_dir} exists and is not empty; choose another --out or --resume {run_dir}")
        run_dir.mkdir(parents=True, exist_ok=True)
        write_text_atomic(run_dir / "command.txt", command + "\n")
        checkpoint = None
    write_text_atomic(run_dir / "config.yml", yaml.safe_dump(cfg, sort_keys=False))
    if cfg["tensorboard"]:
        try:
            import tensorboard  # noqa: F401
        except ImportError:
            raise SystemExit("--tensorboard needs the tensorboard package: pip install tensorboard") from None
    torch.set_num_threads(1)  # small MLPs: extra intra-op threads only contend with the envs for the cores
    print(f"seed: {cfg['seed']}")
    print(f"run directory: {run_dir}")
    model, callbacks, episode_log, evaluation, checkpointer = build(cfg, run_dir, checkpoint)
    remaining = int(cfg["total_timesteps"]) - model.num_timesteps
    if remaining <= 0:
        print(f"already trained for {model.num_timesteps} >= {cfg['total_timesteps']} timesteps; nothing to do")
    else:
        print(f"{cfg['algo']} on {cfg['env_id']} {cfg['env_kwargs']}: timesteps {model.num_timesteps} -> {cfg['total_timesteps']}")
        start = time.perf_counter()
        model.learn(total_timesteps=remaining, callback=callbacks, progress_bar=True,
                    reset_num_timesteps=checkpoint is None, tb_log_name=cfg["algo"])
        print(f"trained in {time.perf_counter() - start:.0f} s ({model.num_timesteps} timesteps)")
        checkpointer.save()
    model.save(run_dir / "model.tmp.zip")
    (run_dir / "model.tmp.zip").replace(run_dir / "model.zip")
    venv = model.get_vec_normalize_env()
    if venv is not None:
        venv.save(str(run_dir / "vecnormalize.pkl.tmp"))
        (run_dir / "vecnormalize.pkl.tmp").replace(run_dir / "vecnormalize.pkl")
    episode_log.write_csv(run_dir / "train_log.csv")
    evals = np.array([np.mean(r) for r in evaluation.evaluations_results])
    write_text_atomic(run_dir / "eval_curve.csv", "timestep,mean_reward,std_reward\n" + "".join(
        f"{t},{m:.6g},{np.std(r):.6g}\n" for t, m, r in zip(evaluation.evaluations_timesteps, evals, evaluation.evaluations_results)))
    learning_curve(run_dir / "learning_curve.png", episode_log.timesteps, episode_log.rewards,
                   evaluation.evaluations_timesteps, evaluation.evaluations_results,
                   title=f"{cfg['algo']} · {cfg['env_id']} · {cfg['env_kwargs']['backend']} · seed {cfg['seed']}")
    if len(evals):
        print(f"val mean reward log(RMSE_rule/RMSE): last {evals[-1]:+.4f}, best {evals.max():+.4f}")
    print(f"wrote {run_dir}")
    return run_dir


if __name__ == "__main__":
    main()
