"""Train a filter tuner (stable-baselines3) on a bboxtune env and write a run directory.

    python scripts/train.py                      # PPO, bboxtune/FilterTune-v0, sim source, ufir_cmn back end, msd features
    python scripts/train.py --backend kf_cmn --seed 1
    python scripts/train.py --resume runs/ppo_ufir_cmn_sim_s0   # continue a killed run
    python scripts/train.py --resume runs/ppo_ufir_cmn_sim_s0 --timesteps 200000   # train it on to 200k in all

Episodes: training draws the train split; every --eval-freq timesteps (at the first step reaching each multiple of
it, also after a resume) the policy is scored on the val split (``bboxtune.agents.splits``: disjoint noise-seed
sets; OTB sources also use the env's sequence splits). Observations are normalised by
VecNormalize (obs only; the rewards, e.g. log(RMSE_rule/RMSE), are already scale-free); config.yml records the
--features set. The run directory layout is in ``bboxtune.agents.training.runs``. Same seed → same result on the same machine
(uninterrupted runs); a resumed run continues from its last checkpoint with reseeded envs (seed + timesteps done), so
it does not replay earlier episodes.

Before anything is written or a worker process starts, the whole configuration is checked in this process: the
hyperparameters, one env of the train and the val split (built and reset), and the model built on the training
envs; a bad setting is one line naming it (exit status 2). The run directory is locked while train.py writes it
(a second train.py on it stops with "DIR is in use by another train.py (pid N)"; the lock dies with the process,
so a killed run can be resumed at once).

--resume DIR continues from DIR's newest complete checkpoint (a corrupt or truncated one is reported by file and
skipped; a run stopped before its first checkpoint starts again from timestep 0). Its settings come from
DIR/config.yml, which a resume never rewrites; only --timesteps and --trust-pickle may be given with it.
--timesteps is always the run's total: with --resume the target to train up to (at least the timesteps already
done), recorded in the checkpoints, so a later resume without --timesteps keeps it; by default the previous
target. Runs and checkpoints hold no pickles; --trust-pickle lets a resume read an old run's
vecnormalize.pkl / replay_buffer.pkl (pickles can run code: only for runs you trust). A resumed run evaluates at
the same steps as an uninterrupted one (the next multiple of --eval-freq after its checkpoint's step).

Ctrl-C (or SIGTERM) stops a run with one line, "train.py: interrupted at step N; resume with: python
scripts/train.py --resume DIR" (N: the step of its newest checkpoint, where the resume continues), exit status 130
(SIGTERM: "terminated", 143).
"""

from __future__ import annotations

import argparse
import platform
import shlex
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import gymnasium
import numpy as np
import stable_baselines3
import torch
import yaml
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import CallbackList
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

from bboxtune import envs  # noqa: F401
from bboxtune.agents.cli import (
    ArgumentParser,
    HelpFormatter,
    Interrupted,
    command,
    existing_dir,
    key_values,
    nonnegative_int,
    out_dir,
    positive_int,
    tracker_set,
)
from bboxtune.agents.evaluation.plots import learning_curve
from bboxtune.agents.training.algos import ALGOS, algo_class
from bboxtune.agents.training.callbacks import (
    AtomicCheckpoint,
    EpisodeLog,
    ProgressBar,
    SaveBest,
    ScheduledEval,
    restore_eval_state,
)
from bboxtune.agents.training.checkpoints import Checkpoint, newest_complete, resume_hint
from bboxtune.agents.training.hyperparams import VEC_ENVS, Hyperparams, constructor_kwargs, load_hyperparams
from bboxtune.agents.training.run_checks import check_new_model, check_tensorboard, hyperparams_of, validated_envs
from bboxtune.agents.training.run_files import (
    PICKLED_REPLAY,
    REPLAY,
    STATS,
    RunError,
    load_normalizer,
    load_replay_buffer,
    save_stats,
)
from bboxtune.agents.training.runs import (
    CONFIG,
    RESUME_KEYS,
    RunLock,
    check_free,
    claim_run_dir,
    describe_held_features,
    load_config,
    make_vec,
    observation_names,
)
from bboxtune.agents.training.safe_load import load_model, stamp
from bboxtune.envs.data.atomic_files import atomic_write, write_text_atomic
from bboxtune.envs.data.otb import TRACKER_SPLIT
from bboxtune.envs.episodes.actions import BACKENDS
from bboxtune.envs.episodes.config import FEATURE_SETS, SOURCES, EnvConfig
from bboxtune.envs.episodes.scoring import reward_label

if TYPE_CHECKING:
    from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

DEFAULT_ENV = "bboxtune/FilterTune-v0"
RESUME_FLAGS = {"--resume", "--timesteps", "--trust-pickle"}  # the only flags a resume takes: the rest is config.yml's


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog="train.py", description=__doc__, formatter_class=HelpFormatter, allow_abbrev=False)
    p.add_argument("--algo", default="ppo", choices=sorted(ALGOS), help="SB3 algorithm")
    p.add_argument("--env", default=DEFAULT_ENV, help="env id (registered by `import envs`)")
    p.add_argument("--backend", default="ufir_cmn", choices=BACKENDS, help="filter back end the tuner sets")
    p.add_argument("--source", default="sim", choices=SOURCES, help="episode source (video: set --env-kwargs detector:NAME)")
    p.add_argument("--reward", default="rmse", choices=("rmse", "iou_precision", "success_auc"), help="env reward")
    p.add_argument("--features", default=None, choices=FEATURE_SETS, help="observation feature set (EnvConfig.features; msd: "
                   "base + the centre's 64-frame mean squared displacement); default: msd for FilterTune-v0, else base")
    p.add_argument("--timesteps", type=positive_int, default=None,
                   help="total env steps of the run (one step = one episode for FilterTune-v0); default: n_timesteps "
                        "of agents/hyperparams/<algo>.yml; with --resume: the total to reach (>= the steps done), "
                        "default the run's previous target")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed of the model, the envs and the train split")
    p.add_argument("--n-envs", type=positive_int, default=None,
                   help="parallel training envs (default: the YAML's n_envs; at most what fits in this machine's available "
                        "memory with the rollout or replay buffer)")
    p.add_argument("--vec", choices=VEC_ENVS, default=None,
                   help="how the training envs run: batched (FilterTune-v0: all in one vectorised batch, this process), "
                        "subproc (one process each) or dummy (one after another, this process); default: the YAML's "
                        "vec_env (ppo: batched where the env has it, else subproc)")
    p.add_argument("--out", type=out_dir, default=None,
                   help="run directory, new or empty (default runs/<algo>_<backend>_<source>_s<seed>)")
    p.add_argument("--resume", type=existing_dir, default=None, metavar="DIR",
                   help="continue the run in DIR from its newest complete checkpoint (settings from DIR/config.yml)")
    p.add_argument("--trust-pickle", action="store_true",
                   help="with --resume: also read an old run's pickled statistics / replay buffer (pickles can run code)")
    p.add_argument("--tensorboard", action="store_true", help="also log to DIR/tensorboard (needs the tensorboard package)")
    p.add_argument("--eval-freq", type=positive_int, default=10_000, help="timesteps between evaluations on the val split")
    p.add_argument("--eval-episodes", type=positive_int, default=200,
                   help="val episodes per evaluation (the same ones each time)")
    p.add_argument("--checkpoint-freq", type=positive_int, default=20_000, help="timesteps between checkpoints")
    p.add_argument("--hyperparams", nargs="*", default=[], metavar="KEY:VALUE",
                   help="override entries of agents/hyperparams/<algo>.yml (YAML values), e.g. n_steps:64 learning_rate:lin_1e-3")
    p.add_argument("--trackers", type=tracker_set, default=None, metavar="SET",
                   help="source otb_tracker (or mix): the trackers whose output episodes replay, one drawn per episode: "
                        "'train' or 'test' of the tracker split (bboxtune.envs.data.otb.TRACKER_SPLIT) or comma-separated names "
                        "(default with those sources: 'train', unless --env-kwargs sets tracker or trackers)")
    p.add_argument("--env-kwargs", nargs="*", default=[], metavar="KEY=VALUE",
                   help="more env arguments (bboxtune.envs.episodes.config.EnvConfig fields, YAML values; KEY=VALUE or "
                        "KEY:VALUE, split at the first = or :), e.g. track_length=200")
    return p


def parse_args(argv: list[str] | None = None, parser: ArgumentParser | None = None) -> argparse.Namespace:
    p = parser or build_parser()
    tokens = list(sys.argv[1:] if argv is None else argv)
    args = p.parse_args(tokens)
    args.hyperparams = _key_values(p, "--hyperparams", args.hyperparams)
    args.env_kwargs = _key_values(p, "--env-kwargs", args.env_kwargs)
    clash = sorted(set(args.env_kwargs) & {"backend", "source", "reward", "features", "split"})
    if clash:
        p.error(f"--env-kwargs {clash}: use --backend/--source/--reward/--features (the split is set per use)")
    if args.features is None:
        args.features = "msd" if args.env == DEFAULT_ENV else "base"
    if args.trackers is not None and "trackers" in args.env_kwargs:
        p.error("--trackers: given twice (also in --env-kwargs trackers=...)")
    if args.trackers is not None:
        args.env_kwargs["trackers"] = list(args.trackers)
    elif draws_trackers(args.source, args.env_kwargs) and not {"tracker", "trackers"} & set(args.env_kwargs):
        args.env_kwargs["trackers"] = list(TRACKER_SPLIT["train"])  # never the held-out trackers by default
    given = sorted({t.split("=", 1)[0] for t in tokens if t.startswith("--")} - RESUME_FLAGS)
    if args.resume is not None and given:
        p.error(f"{' '.join(given)} cannot be given with --resume: the run's settings come from {args.resume / CONFIG} "
                f"(allowed with --resume: {' '.join(sorted(RESUME_FLAGS - {'--resume'}))})")
    if args.trust_pickle and args.resume is None:
        p.error("--trust-pickle applies to --resume only (a new run reads no pickles)")
    return args


def draws_trackers(source: str, env_kwargs: dict[str, Any]) -> bool:
    """Whether episodes replay tracker output: source otb_tracker, or mix with a tracker weight (mix_weights[2], of
    the triple or the 4-tuple with mot) that is not 0 (a malformed value is left to EnvConfig's check)."""
    weights = env_kwargs.get("mix_weights", (1.0, 1.0, 1.0))
    no_trackers = isinstance(weights, (list, tuple)) and len(weights) in (3, 4) and weights[2] == 0
    return source == "otb_tracker" or (source == "mix" and not no_trackers)


def _key_values(p: ArgumentParser, flag: str, items: list[str]) -> dict[str, Any]:
    """``--env-kwargs`` items ``KEY=VALUE`` or ``KEY:VALUE`` (as compare.py), ``--hyperparams`` ``KEY:VALUE``."""
    try:
        return key_values(flag, items, separators="=:" if flag == "--env-kwargs" else ":")
    except ValueError as err:
        p.error(str(err))


def new_config(args: argparse.Namespace) -> dict[str, Any]:
    if args.vec is not None and "vec_env" in args.hyperparams:
        raise RunError("--vec: given twice (also in --hyperparams vec_env:...)")
    overrides = {**args.hyperparams, **({"n_envs": args.n_envs} if args.n_envs else {}),
                 **({"vec_env": args.vec} if args.vec else {})}
    try:
        hp = load_hyperparams(args.algo, args.env, overrides)
    except ValueError as err:  # names the YAML file and the key; the flags that override it come first
        given = [flag for flag, value in (("--hyperparams", args.hyperparams), ("--n-envs", args.n_envs),
                                          ("--vec", args.vec)) if value]
        raise RunError(f"{' / '.join(given)}: {err}" if given else str(err)) from None
    return {
        "algo": args.algo, "env_id": args.env, "seed": args.seed,
        "env_kwargs": {"backend": args.backend, "source": args.source, "reward": args.reward, "features": args.features,
                       **args.env_kwargs},
        "total_timesteps": args.timesteps or hp.n_timesteps,
        "eval_freq": args.eval_freq, "eval_episodes": args.eval_episodes, "checkpoint_freq": args.checkpoint_freq,
        "tensorboard": args.tensorboard, "hyperparams": hp.raw,
        "splits": "train: noise seeds drawn outside [1e9, 3e9); val: 2e9 + i; test: 1e9 + i (agents/splits.py)",
        "versions": {"python": platform.python_version(), "stable_baselines3": stable_baselines3.__version__,
                     "torch": str(torch.__version__), "gymnasium": gymnasium.__version__, "numpy": np.__version__},
        "created": time.strftime("%Y-%m-%d %H:%M:%S"),
    }


def checkpoint_check(cfg: dict[str, Any], hp: Hyperparams, venv: VecEnv, trust_pickle: bool):
    """``check(folder)`` for :func:`bboxtune.agents.training.checkpoints.newest_complete`: the model, its statistics
    and (off-policy)
    its replay buffer load and fit the run's env."""

    def check(folder: Path) -> None:
        model = load_model(folder / "model.zip", cfg, venv)
        if hp.normalize and load_normalizer(folder, venv, training=True, trust_pickle=trust_pickle) is None:
            raise RunError(f"{folder / STATS} is missing")
        if getattr(model, "replay_buffer", None) is not None:
            restore_replay_buffer(model, folder, trust_pickle)

    return check


def restore_replay_buffer(model: BaseAlgorithm, folder: Path, trust_pickle: bool) -> None:
    if (folder / REPLAY).exists():
        load_replay_buffer(model, folder / REPLAY)
    elif not (folder / PICKLED_REPLAY).exists():
        raise RunError(f"{folder / REPLAY} is missing")
    elif not trust_pickle:
        raise RunError(f"{folder / PICKLED_REPLAY}: a pickle, which can run code when loaded; pass --trust-pickle only "
                       "if you trust where this run comes from")
    else:
        # an off-policy model: the callers check that it has a replay buffer; the user vouched for this file
        cast("OffPolicyAlgorithm", model).load_replay_buffer(folder / PICKLED_REPLAY)


def build(cfg: dict[str, Any], hp: Hyperparams, run_dir: Path, checkpoint: Checkpoint | None, target: int,
          trust_pickle: bool):
    """The model (new or loaded from ``checkpoint``), its training VecEnv and the callbacks."""
    state = checkpoint.state if checkpoint is not None else {}
    done = checkpoint.num_timesteps if checkpoint is not None else 0
    seed = int(cfg["seed"]) + done  # resumed envs do not replay the first segment's episodes
    venv = make_vec(cfg["env_id"], cfg["env_kwargs"], split="train", n_envs=hp.n_envs, seed=seed, vec_env=hp.vec_env)
    eval_env = make_vec(cfg["env_id"], cfg["env_kwargs"], split="val", n_envs=1, seed=int(cfg["seed"]),
                        cycle=cfg["eval_episodes"])
    tb = str(run_dir / "tensorboard") if cfg["tensorboard"] else None
    if checkpoint is None:
        if hp.normalize:
            venv = VecNormalize(venv, **hp.normalize)
        n_actions = cast("tuple[int, ...]", venv.action_space.shape)[0]  # a Box
        model = algo_class(cfg["algo"])(hp.policy, venv, seed=int(cfg["seed"]), device="cpu", verbose=0, tensorboard_log=tb,
                                        **constructor_kwargs(hp, n_actions))
    else:
        venv = load_normalizer(checkpoint.folder, venv, training=True, trust_pickle=trust_pickle) or venv
        model = load_model(checkpoint.folder / "model.zip", cfg, venv, tensorboard_log=tb)
        model.set_random_seed(seed)
        model._last_obs = None  # the fresh envs have no episode yet: make learn() reset them
        if getattr(model, "replay_buffer", None) is not None:
            restore_replay_buffer(model, checkpoint.folder, trust_pickle)
    if tb is None:  # SB3's own default logger would leave an empty SB3-<date> folder in the temp directory
        model.set_logger(Logger(folder=None, output_formats=[]))
    stamp(model, cfg)
    if hp.normalize:
        eval_env = VecNormalize(eval_env, training=False, norm_obs=hp.normalize.get("norm_obs", True), norm_reward=False)
    episode_log = EpisodeLog(state.get("episode_timesteps"), state.get("episode_rewards"))
    evaluation = ScheduledEval(eval_env, cfg["eval_freq"], n_eval_episodes=cfg["eval_episodes"], deterministic=True,
                               log_path=str(run_dir), verbose=0, callback_on_new_best=SaveBest(run_dir))
    restore_eval_state(evaluation, state)
    checkpointer = AtomicCheckpoint(run_dir, cfg["checkpoint_freq"], target, episode_log, evaluation)
    return model, CallbackList([episode_log, evaluation, checkpointer]), episode_log, evaluation, checkpointer


def prepare_new(args: argparse.Namespace) -> tuple[dict[str, Any], Hyperparams, Path, RunLock]:
    """Config of a new run, checked in full, then its run directory created and locked."""
    cfg = new_config(args)
    run_dir = args.out or Path("runs") / f"{args.algo}_{args.backend}_{args.source}_s{args.seed}"
    check_free(run_dir)
    hp = hyperparams_of(cfg, "--hyperparams")
    check_tensorboard(cfg)
    venv = validated_envs(cfg, hp, "--env / --env-kwargs / --backend / --source / --reward / --trackers",
                          "--n-envs / --hyperparams")
    check_new_model(cfg, hp, venv, f"--hyperparams / agents/hyperparams/{cfg['algo']}.yml")
    venv.close()
    return cfg, hp, run_dir, claim_run_dir(run_dir)


def prepare_resume(args: argparse.Namespace) -> tuple[dict[str, Any], Hyperparams, Checkpoint | None, int, RunLock]:
    """Config of the run in ``args.resume`` and its newest complete checkpoint, checked under the run lock; the
    target total timesteps."""
    run_dir: Path = args.resume
    where = str(run_dir / CONFIG)
    cfg = load_config(run_dir, RESUME_KEYS)
    lock = RunLock(run_dir).acquire()
    try:
        hp = hyperparams_of(cfg, where)
        check_tensorboard(cfg)
        venv = validated_envs(cfg, hp, where, where)
        checkpoint = newest_complete(run_dir, checkpoint_check(cfg, hp, venv, args.trust_pickle))
        venv.close()
        done = checkpoint.num_timesteps if checkpoint is not None else 0
        if args.timesteps is not None and args.timesteps < done:
            raise RunError(f"--timesteps {args.timesteps} is below the {done} timesteps {run_dir} has done "
                           f"(--timesteps is the run's total: give >= {done})")
        previous = checkpoint.state.get("total_timesteps") if checkpoint is not None else None
        target = args.timesteps or previous or int(cfg["total_timesteps"])
    except BaseException:
        lock.release()
        raise
    return cfg, hp, checkpoint, target, lock


def run(argv: list[str] | None = None) -> Path:
    """Train (or resume) the run the command line ``argv`` names; returns its run directory."""
    parser = build_parser()
    args = parse_args(argv, parser)
    command = shlex.join([Path(sys.executable).name, *sys.argv]) if argv is None else shlex.join(["train.py", *argv])
    try:
        if args.resume is None:
            cfg, hp, run_dir, lock = prepare_new(args)
            checkpoint, target = None, int(cfg["total_timesteps"])
        else:
            run_dir = args.resume
            cfg, hp, checkpoint, target, lock = prepare_resume(args)
    except RunError as err:
        parser.error(str(err))
    with lock:
        try:
            if args.resume is None:
                write_text_atomic(run_dir / CONFIG, yaml.safe_dump(cfg, sort_keys=False))
                write_text_atomic(run_dir / "command.txt", command + "\n")
            else:
                with open(run_dir / "command.txt", "a") as fh:
                    fh.write(command + "\n")
            return train(cfg, hp, run_dir, checkpoint, target, args.trust_pickle)
        except KeyboardInterrupt as stop:  # Ctrl-C, or SIGTERM (bboxtune.agents.cli.command)
            raise Interrupted.of(stop, resume_hint(run_dir)) from None


def train(cfg: dict[str, Any], hp: Hyperparams, run_dir: Path, checkpoint: Checkpoint | None, target: int,
          trust_pickle: bool) -> Path:
    """Train the run up to ``target`` timesteps (from ``checkpoint`` if given) and write its final files."""
    torch.set_num_threads(1)  # small MLPs: extra intra-op threads only contend with the envs for the cores
    print(f"seed: {cfg['seed']}")
    print(f"run directory: {run_dir}")
    if checkpoint is not None:
        print(f"resuming from {checkpoint.folder}")
    model, callbacks, episode_log, evaluation, checkpointer = build(cfg, hp, run_dir, checkpoint, target, trust_pickle)
    remaining = target - model.num_timesteps
    if remaining <= 0:
        print(f"already trained for {model.num_timesteps} >= {target} timesteps; nothing to do")
    else:
        print(f"{cfg['algo']} on {cfg['env_id']} {cfg['env_kwargs']}: timesteps {model.num_timesteps} -> {target}")
        start = time.perf_counter()
        progress = ProgressBar()
        try:
            model.learn(total_timesteps=remaining, callback=CallbackList([callbacks, progress]),
                        reset_num_timesteps=checkpoint is None, tb_log_name=cfg["algo"])
        finally:
            progress.close()
        print(f"trained in {time.perf_counter() - start:.0f} s ({model.num_timesteps} timesteps)")
        checkpointer.save()
    atomic_write(run_dir / "model.zip", model.save)
    venv = model.get_vec_normalize_env()
    if venv is not None:
        save_stats(venv, run_dir / STATS)
        print("inputs that never varied in training (held at their training value wherever the tuner is applied): "
              + describe_held_features({cfg["algo"]: venv},
                                       {cfg["algo"]: observation_names(cfg["env_id"], cfg["env_kwargs"])}))
    episode_log.write_csv(run_dir / "train_log.csv")
    evals = np.array([np.mean(r) for r in evaluation.evaluations_results])
    write_text_atomic(run_dir / "eval_curve.csv", "timestep,mean_reward,std_reward\n" + "".join(
        f"{t},{m:.6g},{np.std(r):.6g}\n"
        for t, m, r in zip(evaluation.evaluations_timesteps, evals, evaluation.evaluations_results, strict=False)))
    learning_curve(run_dir / "learning_curve.png", episode_log.timesteps, episode_log.rewards,
                   evaluation.evaluations_timesteps, evaluation.evaluations_results,
                   title=f"{cfg['algo']} · {cfg['env_id']} · {cfg['env_kwargs']['backend']} · seed {cfg['seed']}")
    model.get_env().close()
    evaluation.eval_env.close()
    if len(evals):
        env_cfg = EnvConfig.from_kwargs(**cfg["env_kwargs"])
        print(f"val mean reward ({reward_label(env_cfg.reward, env_cfg.reward_baseline)}): last {evals[-1]:+.4f}, "
              f"best {evals.max():+.4f}")
    print(f"wrote {run_dir}")
    return run_dir


@command
def main(argv: list[str] | None = None) -> int:
    """The command line: :func:`run`; exit status 0 (a bad argument exits 2 with one line, Ctrl-C 130)."""
    run(argv)
    return 0
