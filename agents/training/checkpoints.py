"""Checkpoints of a training run: atomic writes, and on resume the newest complete one.

``checkpoints/ckpt_<num_timesteps, 12 digits>/`` holds ``model.zip``, ``vecnormalize.json`` (if the run
normalises observations), ``replay_buffer.npz`` (off-policy algorithms) and ``state.json``
(``num_timesteps``, the resume target ``total_timesteps``, the episode log and the EvalCallback state). A
folder is written under ``<name>.tmp`` and renamed when complete (the commit point); ``checkpoints/latest``
then names it (replaced atomically). On resume every folder is checked, newest first
(:func:`newest_complete`): ``state.json`` parses and matches the folder, and the caller's check (model,
statistics, replay buffer load and fit the run) passes; a folder or a ``latest`` that fails is reported by
file and skipped, so a truncated or corrupt checkpoint falls back to the newest complete one.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from stable_baselines3.common.base_class import BaseAlgorithm

from bboxtune.agents.training.run_files import REPLAY, STATS, RunError, read_json, save_replay_buffer, save_stats
from bboxtune.envs.data import textfile
from bboxtune.envs.data.atomic_files import write_text_atomic

CHECKPOINTS = "checkpoints"
LATEST = "latest"
STATE = "state.json"
_NAME = re.compile(r"ckpt_([0-9]{12})")  # fullmatch only: a fixed-width name, no path separators


@dataclass(frozen=True)
class Checkpoint:
    """A checked checkpoint folder and its ``state.json``."""

    folder: Path
    state: dict[str, Any]

    @property
    def num_timesteps(self) -> int:
        return int(self.state["num_timesteps"])


def checkpoint_name(num_timesteps: int) -> str:
    return f"ckpt_{num_timesteps:012d}"


def save_checkpoint(run_dir: Path, model: BaseAlgorithm, state: dict[str, Any], keep: int = 2) -> Path:
    """Write ``checkpoints/ckpt_<num_timesteps>/`` as described above, point ``latest`` at it, and delete all
    but the ``keep`` newest checkpoints (never the new one). Returns the checkpoint folder."""
    root = Path(run_dir) / CHECKPOINTS
    root.mkdir(parents=True, exist_ok=True)
    name = checkpoint_name(model.num_timesteps)
    final, tmp, old = root / name, root / (name + ".tmp"), root / (name + ".old")
    for leftover in root.iterdir():  # of a killed save (the caller holds the run lock: nobody else writes here)
        if leftover.suffix in (".tmp", ".old") and leftover.is_dir():
            shutil.rmtree(leftover)
    tmp.mkdir()
    model.save(tmp / "model.zip")
    venv = model.get_vec_normalize_env()
    if venv is not None:
        save_stats(venv, tmp / STATS)
    if getattr(model, "replay_buffer", None) is not None:
        save_replay_buffer(model, tmp / REPLAY)
    (tmp / STATE).write_text(json.dumps({"num_timesteps": int(model.num_timesteps), **state}))
    if final.exists():  # a folder of the same step (e.g. a corrupt one skipped on resume): set aside, not deleted first
        os.replace(final, old)
    os.replace(tmp, final)
    write_text_atomic(root / LATEST, name + "\n")
    shutil.rmtree(old, ignore_errors=True)
    for stale in sorted(p for p in root.iterdir() if _NAME.fullmatch(p.name) and p.is_dir())[:-keep]:
        if stale != final:
            shutil.rmtree(stale, ignore_errors=True)
    return final


def read_state(folder: Path) -> dict[str, Any]:
    """``folder/state.json``, checked: an object whose ``num_timesteps`` equals the folder's number."""
    path = Path(folder) / STATE
    if not path.is_file():
        raise RunError(f"{path} is missing")
    state = read_json(path)
    steps = state.get("num_timesteps") if isinstance(state, dict) else None
    match = _NAME.fullmatch(Path(folder).name)
    if not isinstance(steps, int) or isinstance(steps, bool) or match is None or steps != int(match.group(1)):
        raise RunError(f"{path}: num_timesteps={steps!r} does not match the folder name {Path(folder).name}")
    for key in ("episode_timesteps", "episode_rewards", "eval_timesteps", "eval_results", "eval_lengths"):
        if not isinstance(state.get(key, []), list):
            raise RunError(f"{path}: {key} must be a list")
    if len(state.get("episode_timesteps", [])) != len(state.get("episode_rewards", [])):
        raise RunError(f"{path}: episode_timesteps and episode_rewards differ in length")
    target = state.get("total_timesteps")
    if target is not None and (not isinstance(target, int) or isinstance(target, bool) or target < 1):
        raise RunError(f"{path}: total_timesteps={target!r}; expected an integer >= 1")
    return state


def _pointer(root: Path, log: Callable[[str], None]) -> str | None:
    """The folder name in ``latest`` (None, reported through ``log``, if it is missing or malformed)."""
    path = root / LATEST
    if not path.exists():
        return None
    try:
        name = textfile.read_bytes(path, limit=64).decode("ascii").strip()
    except (ValueError, UnicodeDecodeError) as err:
        log(f"{path}: unreadable ({err}); using the checkpoint folders themselves")
        return None
    if not _NAME.fullmatch(name):
        log(f"{path}: {name[:40]!r} is not a checkpoint name; using the checkpoint folders themselves")
        return None
    return name


def resume_hint(run_dir: Path) -> str:
    """Where a stopped run stands and the command that continues it: ``at step N; resume with: python
    scripts/train.py --resume DIR``, N the step of the newest checkpoint folder by name (a folder gets its name
    when complete; the resume still checks it: :func:`newest_complete`), or ``before its first checkpoint; ...``."""
    root = Path(run_dir) / CHECKPOINTS
    steps = [int(m.group(1)) for p in (root.iterdir() if root.is_dir() else ()) if (m := _NAME.fullmatch(p.name))]
    resume = f"resume with: python scripts/train.py --resume {shlex.quote(str(run_dir))}"
    if not steps:
        return f"before its first checkpoint; {resume} (it starts again from step 0)"
    return f"at step {max(steps)}; {resume}"


def newest_complete(run_dir: Path, check: Callable[[Path], None], log: Callable[[str], None] = print) -> Checkpoint | None:
    """The newest checkpoint of ``run_dir`` whose ``state.json`` reads and for which ``check(folder)`` (raising
    :class:`RunError` for a bad file) passes; each skipped folder is reported through ``log``. None if the run
    has no checkpoint folder; :class:`RunError` if it has some but none is complete."""
    root = Path(run_dir) / CHECKPOINTS
    entries = root.iterdir() if root.is_dir() else iter(())
    folders = sorted((p for p in entries if _NAME.fullmatch(p.name) and p.is_dir()), reverse=True)
    pointed = _pointer(root, log)
    if pointed is not None and not (root / pointed).is_dir():
        log(f"{root / LATEST}: names {pointed}, which does not exist; using the checkpoint folders themselves")
    problems = []
    for folder in folders:
        try:
            state = read_state(folder)
            check(folder)
        except RunError as err:
            log(f"skipping checkpoint {folder.name}: {err}")
            problems.append(str(err))
            continue
        if pointed is not None and pointed != folder.name:
            log(f"{root / LATEST} names {pointed}; resuming from the newest complete checkpoint {folder.name}")
        return Checkpoint(folder, state)
    if problems:
        raise RunError(f"{root}: no complete checkpoint ({len(problems)} checked; newest: {problems[0]})")
    return None
