"""Train / validation / test splits of episodes, as disjoint sets of noise seeds.

An episode of ``bboxtune/FilterTune-v0`` is a pure function of ``(sequence, noise_seed)``. For the simulated
source the splits are therefore sets of noise seeds (for OTB sources the env's ``split=`` argument also picks
disjoint sequence sets; the noise seeds below apply on top):

| split | noise seeds                                                  | who uses it                            |
|-------|--------------------------------------------------------------|----------------------------------------|
| test  | ``TEST_BASE + i``, i = 0, 1, …  (10⁹ + i)                     | ``scripts/compare.py`` (fixed, paired) |
| val   | ``VAL_BASE + i``, i = 0, 1, …   (2·10⁹ + i)                   | EvalCallback of ``scripts/train.py``   |
| train | uniform on [0, 2⁶²) minus [10⁹, 3·10⁹), redrawn if inside it | RL training; global / amortised fits   |

The exclusion is explicit, so no training episode can be a validation or test episode (without it the chance
that 10⁶ training draws hit one of 10⁴ evaluation seeds would be ~2·10⁻⁹ anyway).

Which episodes an evaluation scores (``scripts/compare.py --split --seed``, :func:`split_seeds`): for val / test,
seed 0 takes episodes 0 … n − 1 of the split and any other seed n distinct episode indices drawn uniformly from
[0, 10⁹) with ``default_rng((seed, 1))``; for train, :func:`train_seeds` with ``default_rng((seed, 1))`` (not the
``default_rng(seed)`` stream the baselines are fitted on, so they are not scored on their own fitting episodes).
The same seed always gives the same episodes. OTB sources enumerate their episodes instead
(:func:`otb_episodes`): every sequence of the split × k noise seeds (source "otb") or × every tracker of the
env's set (source "otb_tracker", whose episodes do not depend on the noise seed), the j-th episode taking the
j-th of :func:`split_seeds`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from bboxtune.envs.episodes.config import SPLITS

TEST_BASE = 10**9
VAL_BASE = 2 * 10**9
RESERVED = (10**9, 3 * 10**9)  # [low, high): seeds the train split never uses
SPLIT_SIZE = 10**9  # at most this many val / test episodes
SEED_HIGH = 2**62



def eval_seeds(split: str, n: int, start: int = 0) -> np.ndarray:
    """The noise seeds of episodes ``start .. start + n - 1`` of the ``"val"`` or ``"test"`` split."""
    if split not in ("val", "test"):
        raise ValueError(f"split={split!r}; allowed: 'val', 'test' (the train split is drawn at random)")
    if n < 0 or start < 0 or start + n > SPLIT_SIZE:
        raise ValueError(f"episodes [{start}, {start + n}) out of range: allowed 0 <= start <= start + n <= {SPLIT_SIZE}")
    base = TEST_BASE if split == "test" else VAL_BASE
    return base + np.arange(start, start + n, dtype=np.int64)


def train_seeds(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` noise seeds of the train split drawn with ``rng`` (uniform on [0, 2⁶²) outside ``RESERVED``)."""
    seeds = rng.integers(SEED_HIGH, size=n, dtype=np.int64)
    bad = (seeds >= RESERVED[0]) & (seeds < RESERVED[1])
    while bad.any():  # probability 5e-10 per draw: practically never loops
        seeds[bad] = rng.integers(SEED_HIGH, size=int(bad.sum()), dtype=np.int64)
        bad = (seeds >= RESERVED[0]) & (seeds < RESERVED[1])
    return seeds


def split_seeds(split: str, n: int, seed: int = 0) -> np.ndarray:
    """The noise seeds of the ``n`` episodes of ``split`` that an evaluation with ``seed`` scores (module
    docstring): distinct, the same for the same arguments; seed 0 of val / test is :func:`eval_seeds`."""
    if split not in SPLITS:
        raise ValueError(f"split={split!r}; allowed: {SPLITS}")
    if not 0 <= n <= SPLIT_SIZE or seed < 0:
        raise ValueError(f"n={n}, seed={seed}; allowed: 0 <= n <= {SPLIT_SIZE}, seed >= 0")
    rng = np.random.default_rng((seed, 1))
    if split == "train":
        seeds = train_seeds(rng, n)
        while len(np.unique(seeds)) < n:  # a repeat among 2⁶² values: practically never
            seeds = train_seeds(rng, n)
        return seeds
    if seed == 0:
        return eval_seeds(split, n)
    index = rng.integers(SPLIT_SIZE, size=n, dtype=np.int64)
    while True:  # redraw repeated indices until all n are distinct
        _, first = np.unique(index, return_index=True)
        if len(first) == n:
            break
        again = np.ones(n, dtype=bool)
        again[first] = False
        index[again] = rng.integers(SPLIT_SIZE, size=int(again.sum()), dtype=np.int64)
    return (TEST_BASE if split == "test" else VAL_BASE) + index


@dataclass(frozen=True)
class EpisodeSpec:
    """One evaluation episode: its noise seed and, for OTB sources, the sequence and tracker it is pinned to."""

    noise_seed: int
    sequence: str | None = None
    tracker: str | None = None

    def options(self) -> dict[str, Any]:
        """The env's reset options that replay this episode."""
        pinned = {"sequence": self.sequence, "tracker": self.tracker}
        return {"noise_seed": int(self.noise_seed), **{k: v for k, v in pinned.items() if v is not None}}


def otb_episodes(sequences: Sequence[str], trackers: Sequence[str], split: str, *, seeds_per_sequence: int = 1,
                 seed: int = 0, has_output: Callable[[str, str], bool] = lambda tracker, sequence: True,
                 ) -> list[EpisodeSpec]:
    """Every episode of an OTB source, sequence by sequence: ``seeds_per_sequence`` noise seeds per sequence
    (``trackers`` empty: source "otb"), or one episode per tracker in ``trackers`` that ``has_output`` for the
    sequence (source "otb_tracker"; its episodes do not depend on the noise seed, so there it must be 1). The
    j-th episode gets the j-th of :func:`split_seeds` ``(split, n, seed)``."""
    if seeds_per_sequence < 1 or (trackers and seeds_per_sequence != 1):
        raise ValueError(f"seeds_per_sequence={seeds_per_sequence}; allowed: >= 1, and 1 with trackers")
    pins = [(name, t) for name in sequences for t in trackers if has_output(t, name)] if trackers else \
        [(name, None) for name in sequences for _ in range(seeds_per_sequence)]
    seeds = split_seeds(split, len(pins), seed)
    return [EpisodeSpec(int(s), name, t) for s, (name, t) in zip(seeds, pins, strict=False)]


def split_of(noise_seed: int) -> str:
    """Which split a noise seed belongs to."""
    if TEST_BASE <= noise_seed < TEST_BASE + SPLIT_SIZE:
        return "test"
    if VAL_BASE <= noise_seed < VAL_BASE + SPLIT_SIZE:
        return "val"
    return "train"


class SplitSeeds(gym.Wrapper):
    """Pins every ``reset`` of the wrapped env to a noise seed of one split.

    ``"train"``: seeds drawn by :func:`train_seeds` from the wrapper's own generator, re-created by
    ``reset(seed=s)`` (so ``make_vec_env(seed=...)`` makes training reproducible). ``"val"``/``"test"``: the
    seeds of episodes 0, 1, …, ``cycle − 1`` in turn, then again from 0 (``reset(seed=...)`` restarts at 0), so
    an evaluation of ``cycle`` consecutive episodes always covers the same set. A caller's own
    ``options={"noise_seed": s}`` is passed through unchanged.
    """

    def __init__(self, env: gym.Env, split: str = "train", cycle: int = 100) -> None:
        super().__init__(env)
        if split not in SPLITS:
            raise ValueError(f"split={split!r}; allowed: {SPLITS}")
        if split != "train" and not 1 <= cycle <= SPLIT_SIZE:
            raise ValueError(f"cycle={cycle!r}; allowed: 1 <= cycle <= {SPLIT_SIZE}")
        self.split = split
        self.cycle = int(cycle)
        self._seed_rng = np.random.default_rng()
        self._next = 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        if seed is not None:
            self._seed_rng = np.random.default_rng(seed)
            self._next = 0
        options = dict(options or {})
        if "noise_seed" not in options:
            if self.split == "train":
                options["noise_seed"] = int(train_seeds(self._seed_rng, 1)[0])
            else:
                options["noise_seed"] = int(eval_seeds(self.split, 1, start=self._next)[0])
                self._next = (self._next + 1) % self.cycle
        return self.env.reset(seed=seed, options=options)
