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
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

TEST_BASE = 10**9
VAL_BASE = 2 * 10**9
RESERVED = (10**9, 3 * 10**9)  # [low, high): seeds the train split never uses
SPLIT_SIZE = 10**9  # at most this many val / test episodes
SEED_HIGH = 2**62

SPLITS = ("train", "val", "test")


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
