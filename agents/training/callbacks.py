"""SB3 callbacks of ``scripts/train.py``: training-episode log, evaluations on a schedule of timesteps that resumes keep,
atomic checkpoints, the best model and its statistics."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback, ProgressBarCallback
from stable_baselines3.common.vec_env import VecEnv

from bboxtune.agents.training.checkpoints import save_checkpoint
from bboxtune.agents.training.run_files import STATS, save_stats
from bboxtune.envs.data.atomic_files import atomic_write, write_text_atomic


class EpisodeLog(BaseCallback):
    """Records (timestep, episode reward) of every finished training episode (from Monitor's info)."""

    def __init__(self, timesteps: list[int] | None = None, rewards: list[float] | None = None) -> None:
        super().__init__()
        self.timesteps: list[int] = list(timesteps or [])
        self.rewards: list[float] = list(rewards or [])

    def _on_step(self) -> bool:
        for info in self.locals.get("infos", []):
            if "episode" in info:
                self.timesteps.append(int(self.num_timesteps))
                self.rewards.append(float(info["episode"]["r"]))
        return True

    def write_csv(self, path: Path) -> None:
        rows = "\n".join(f"{t},{r:.6g}" for t, r in zip(self.timesteps, self.rewards, strict=False))
        write_text_atomic(path, "timestep,reward\n" + rows + ("\n" if rows else ""))


class SaveBest(BaseCallback):
    """Called by EvalCallback on a new best model: writes ``best_model.zip`` and ``best_vecnormalize.json`` into
    ``run_dir`` (each atomically; EvalCallback's own ``best_model_save_path`` writes in place, so it is unset)."""

    def __init__(self, run_dir: Path) -> None:
        super().__init__()
        self.run_dir = Path(run_dir)

    def _on_step(self) -> bool:
        atomic_write(self.run_dir / "best_model.zip", self.model.save)
        venv = self.model.get_vec_normalize_env()
        if venv is not None:
            save_stats(venv, self.run_dir / f"best_{STATS}")
        return True


class ScheduledEval(EvalCallback):
    """SB3's EvalCallback on a schedule of timesteps: it evaluates at the first step at which ``num_timesteps``
    reaches or passes a multiple of ``every`` (with n envs, ``num_timesteps`` grows by n per step). SB3's own
    schedule counts its calls, which restart at 0 with every ``learn()``, so each resume restarted it; here a run
    resumed from a checkpoint at step s evaluates next at the first multiple of ``every`` above s, the steps at
    which an uninterrupted run evaluates. Everything else (the evaluation, ``evaluations.npz``, the best
    model callback) is EvalCallback's; its other keyword arguments are passed on."""

    def __init__(self, eval_env: VecEnv, every: int, **kwargs: Any) -> None:
        super().__init__(eval_env, eval_freq=1, **kwargs)  # every call that gets through _on_step evaluates
        self.every = int(every)
        self.due = self.every

    def _on_training_start(self) -> None:
        self.due = self._next_after(self.model.num_timesteps)

    def _next_after(self, timesteps: int) -> int:
        return (timesteps // self.every + 1) * self.every

    def _on_step(self) -> bool:
        if self.num_timesteps < self.due:
            return True
        self.due = self._next_after(self.num_timesteps)
        return super()._on_step()


def eval_state(cb: EvalCallback) -> dict[str, Any]:
    """What an EvalCallback must get back on resume (its log and best score), JSON-serialisable."""
    return {"eval_timesteps": [int(t) for t in cb.evaluations_timesteps],
            "eval_results": [np.asarray(r).tolist() for r in cb.evaluations_results],
            "eval_lengths": [np.asarray(r).tolist() for r in cb.evaluations_length],
            "best_mean_reward": float(cb.best_mean_reward) if np.isfinite(cb.best_mean_reward) else None}


def restore_eval_state(cb: EvalCallback, state: dict[str, Any]) -> None:
    cb.evaluations_timesteps = list(state.get("eval_timesteps", []))
    cb.evaluations_results = [list(r) for r in state.get("eval_results", [])]
    cb.evaluations_length = [list(r) for r in state.get("eval_lengths", [])]
    best = state.get("best_mean_reward")
    cb.best_mean_reward = -np.inf if best is None else float(best)


class AtomicCheckpoint(BaseCallback):
    """Every ``every`` timesteps (checked when a rollout starts, i.e. after the previous update, so that
    everything counted in ``num_timesteps`` has been learnt from) writes a checkpoint with
    :func:`bboxtune.agents.training.checkpoints.save_checkpoint`: the episode log, the EvalCallback state and the run's target
    ``total_timesteps`` (what a resume without ``--timesteps`` trains to)."""

    def __init__(self, run_dir: Path, every: int, total_timesteps: int, episode_log: EpisodeLog,
                 evaluation: EvalCallback) -> None:
        super().__init__()
        self.run_dir = Path(run_dir)
        self.every = int(every)
        self.total_timesteps = int(total_timesteps)
        self.episode_log = episode_log
        self.evaluation = evaluation
        self.last = 0

    def _on_training_start(self) -> None:
        self.last = self.model.num_timesteps

    def _on_rollout_start(self) -> None:
        if self.model.num_timesteps - self.last >= self.every:
            self.save()

    def _on_step(self) -> bool:
        return True

    def save(self) -> Path:
        self.last = self.model.num_timesteps
        state = {"total_timesteps": self.total_timesteps, "episode_timesteps": self.episode_log.timesteps,
                 "episode_rewards": self.episode_log.rewards, **eval_state(self.evaluation)}
        return save_checkpoint(self.run_dir, self.model, state)


class ProgressBar(ProgressBarCallback):
    """SB3's progress bar (tqdm.rich), which :meth:`close` closes also when training stops early. SB3 closes it at
    the end of training only: after Ctrl-C the bar was left open until tqdm's ``__del__`` at interpreter shutdown,
    where rich, stopping its live display, fails with a second traceback ("ImportError: sys.meta_path is None,
    Python is likely shutting down")."""

    def close(self) -> None:
        """Close the bar if one was opened (closing a closed bar does nothing)."""
        pbar = getattr(self, "pbar", None)
        if pbar is not None:
            pbar.close()
