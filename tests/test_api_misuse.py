"""Misuse of the public Python API: every bad call raises ValueError or TypeError whose message names the argument,
within a time bound, and allocates nothing large before it refuses.

The catalogue covers what a user calls: :func:`bboxtune.filters.make` / ``constant_velocity`` / ``Filter.run`` /
``run_from``, the envs (``gym.make`` keyword arguments, ``reset``, ``step``, ``score``, :func:`bboxtune.envs.make_vec`),
:func:`bboxtune.agents.tune` / :func:`~bboxtune.agents.smooth` and the OTB metrics. ``python tests/test_api_misuse.py``
prints the tally (refused as documented / not) for a closing note.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import bboxtune
from bboxtune import agents, envs, filters
from bboxtune.envs.data import metrics

SECONDS = 20.0  # a bad call refuses within this (generous: shared CI machines)
NAN, INF = float("nan"), float("inf")


@dataclass(frozen=True)
class Call:
    """One bad call: ``run()`` must raise ValueError / TypeError whose message contains ``names``."""

    id: str
    run: Callable[[], Any]
    names: str

    def __str__(self) -> str:
        return self.id


def _model(ndim: int = 4) -> filters.StateSpaceModel:
    return filters.constant_velocity(1 / 30, ndim=ndim)


def _track(T: int = 40) -> np.ndarray:
    t = np.arange(T, dtype=float)[:, None]
    return np.hstack([100 + t, 50 + 0.5 * t, np.full((T, 1), 30.0), np.full((T, 1), 60.0)])


def _with(row: int, col: int, value: float, T: int = 40) -> np.ndarray:
    boxes = _track(T)
    boxes[row, col] = value
    return boxes


def _without(variable: str, run: Callable[[], Any]) -> Any:
    """``run()`` with the environment variable ``variable`` unset."""
    saved = os.environ.pop(variable, None)
    try:
        return run()
    finally:
        if saved is not None:
            os.environ[variable] = saved


def _env(**kwargs: Any) -> Any:
    env = gym.make(bboxtune.TUNE_ID, **{"track_length": 64, **kwargs})
    env.reset(seed=0)
    return env


def _retune(**kwargs: Any) -> Any:
    env = gym.make(bboxtune.RETUNE_ID, track_length=64, window=16, **kwargs)
    env.reset(seed=0)
    return env


def _make_calls() -> list[Call]:
    calls: list[Call] = []

    def add(id: str, names: str, run: Callable[[], Any]) -> None:
        calls.append(Call(id, run, names))

    # filters.make and the model
    add("make unknown name", "nope", lambda: filters.make("nope", _model()))
    add("make name None", "name", lambda: filters.make(None, _model()))  # type: ignore[arg-type]
    add("make name list", "name", lambda: filters.make(["kf"], _model()))  # type: ignore[arg-type]
    add("make model None", "model", lambda: filters.make("kf", None))  # type: ignore[arg-type]
    add("make model str", "model", lambda: filters.make("kf", "cv"))  # type: ignore[arg-type]
    add("make unknown parameter", "bogus", lambda: filters.make("kf", _model(), bogus=1.0))
    for name, param, value in [("kf", "sigma_w", "1"), ("kf", "sigma_w", None), ("kf", "sigma_w", True),
                               ("kf", "sigma_w", NAN), ("kf", "sigma_w", -1.0), ("kf", "sigma_v", INF),
                               ("kf", "sigma_v", [1.0, "a"]), ("kf_cmn", "psi", 1.5), ("kf_cmn", "psi", "0.5"),
                               ("ufir", "horizon", 1), ("ufir", "horizon", 2.5), ("ufir", "horizon", "10"),
                               ("ufir", "horizon", 10**12), ("ufir_cmn", "psi", -0.1), ("ofir", "horizon", 0),
                               ("oufir", "horizon", NAN), ("ufir_cmn", "horizon", True),
                               ("bytetrack_kf", "std_weight_position", 0.0),
                               ("bytetrack_kf", "std_weight_velocity", "1/160"), ("ukf", "sigma_w", -5.0)]:
        add(f"make {name} {param}={value!r}", param, lambda n=name, p=param, v=value: filters.make(n, _model(), **{p: v}))
    add("constant_velocity tau 0", "tau", lambda: filters.constant_velocity(0.0))
    add("constant_velocity tau nan", "tau", lambda: filters.constant_velocity(NAN))
    add("constant_velocity tau str", "tau", lambda: filters.constant_velocity("0.1"))  # type: ignore[arg-type]
    add("constant_velocity ndim 0", "ndim", lambda: filters.constant_velocity(0.1, ndim=0))
    add("constant_velocity ndim 2.5", "ndim", lambda: filters.constant_velocity(0.1, ndim=2.5))  # type: ignore[arg-type]

    # Filter.run / run_from
    def run(name: str, y: Any, **params: Any) -> Any:
        return filters.make(name, _model(), **params).run(y)

    for name in ("kf", "ufir_cmn", "bytetrack_kf"):
        add(f"{name} run y 3 columns", "y", lambda n=name: run(n, np.zeros((10, 3))))
        add(f"{name} run y 4-d", "y", lambda n=name: run(n, np.zeros((2, 2, 10, 4))))
        add(f"{name} run y strings", "y", lambda n=name: run(n, np.array([["a"] * 4] * 10)))
        add(f"{name} run y inf", "y", lambda n=name: run(n, _with(3, 0, INF)))
        add(f"{name} run y 1e300", "y", lambda n=name: run(n, _with(3, 0, 1e300)))
        add(f"{name} run y None", "y", lambda n=name: run(n, None))
        add(f"{name} run u wrong shape", "u", lambda n=name: filters.make(n, _model()).run(_track(), u=np.zeros((3, 3))))
    add("bytetrack_kf run negative height", "y", lambda: run("bytetrack_kf", _with(5, 3, -4.0)))
    add("kf per-track sigma_w wrong length", "sigma_w",
        lambda: filters.make("kf", _model(), sigma_w=np.ones(3)).run(np.zeros((2, 10, 4))))
    add("kf run_from carry of another shape", "carry",
        lambda: filters.make("kf", _model()).run_from(np.zeros((2, 5, 4)), filters.make("kf", _model()).run_from(
            np.zeros((3, 5, 4)))[1]))
    add("kf run_from carry str", "carry", lambda: filters.make("kf", _model()).run_from(np.zeros((5, 4)), "carry"))

    # envs: gym.make keyword arguments
    for kwarg, value in [("backend", "nope"), ("source", "nope"), ("reward", "nope"), ("track_length", 3),
                         ("track_length", 10**9), ("track_length", "100"), ("psi_range", (0.5, 0.2)),
                         ("psi_range", (0.0, 1.5)), ("sigma_w_range", (NAN, 1.0)), ("tau_range", (0.0, 0.1)),
                         ("box_size_range", (-1.0, 5.0)), ("motion", "teleport"), ("scenario", "nope"),
                         ("miss_rate_range", (0.0, 1.2)), ("mix_weights", (1.0, -1.0, 0.0)), ("split", "holdout"),
                         ("window", 0), ("history", -1), ("horizon_max", 1),
                         ("sigma_decades", -1.0), ("nominal_psi", 1.0), ("bogus", 1)]:
        add(f"gym.make {kwarg}={value!r}", kwarg,
            lambda k=kwarg, v=value: gym.make(bboxtune.TUNE_ID, **{k: v}).reset(seed=0))
    add("gym.make source otb no root", "otb_root", lambda: _without("OTB_ROOT", lambda: gym.make(bboxtune.TUNE_ID,
                                                                                              source="otb").reset(seed=0)))
    add("gym.make source mot missing root", "mot_root",
        lambda: gym.make(bboxtune.TUNE_ID, source="mot", mot_root="/nonexistent/mot").reset(seed=0))
    add("retune window > track", "window", lambda: gym.make(bboxtune.RETUNE_ID, track_length=64, window=100).reset(seed=0))

    # envs: reset / step / score
    add("reset seed -1", "seed", lambda: gym.make(bboxtune.TUNE_ID, track_length=64).reset(seed=-1))
    add("reset seed str", "seed", lambda: gym.make(bboxtune.TUNE_ID, track_length=64).reset(seed="0"))
    add("reset options bogus", "options", lambda: gym.make(bboxtune.TUNE_ID, track_length=64).reset(
        seed=0, options={"bogus": 1}))
    for label, action in [("3 values", np.zeros(3)), ("nan", np.array([NAN, 0.0])), ("1.5", np.array([1.5, 0.0])),
                          ("str", "a"), ("None", None), ("2-d", np.zeros((2, 2))), ("inf", np.array([0.0, INF]))]:
        add(f"step action {label}", "action", lambda a=action: _env().step(a))
        add(f"retune step action {label}", "action", lambda a=action: _retune().step(a))
    add("score wrong shape", "actions", lambda: _env().unwrapped.score(np.zeros((4, 3))))
    add("score nan", "actions", lambda: _env().unwrapped.score(np.full((4, 2), NAN)))
    add("score outside [-1, 1]", "actions", lambda: _env().unwrapped.score(np.full((4, 2), 2.0)))
    add("score 10^7 actions", "actions", lambda: _env(track_length=500).unwrapped.score(np.zeros((10**7, 2))))
    add("make_vec n 0", "n_envs", lambda: envs.make_vec(bboxtune.TUNE_ID, 0))
    add("make_vec n -3", "n_envs", lambda: envs.make_vec(bboxtune.TUNE_ID, -3))
    add("make_vec n 2.5", "n_envs", lambda: envs.make_vec(bboxtune.TUNE_ID, 2.5))  # type: ignore[arg-type]
    add("make_vec n 10^7", "n_envs", lambda: envs.make_vec(bboxtune.TUNE_ID, 10**7, track_length=500).reset(seed=0))
    add("make_vec bad kwarg", "backend", lambda: envs.make_vec(bboxtune.TUNE_ID, 2, backend="nope"))

    # agents.tune / smooth
    for label, boxes in [("3 columns", np.zeros((40, 3))), ("1e300", _with(5, 0, 1e300)), ("inf", _with(5, 1, INF)),
                         ("1.0000001e7", _with(5, 1, 1.0000001e7)), ("zero width", _with(5, 2, 0.0)),
                         ("strings", np.array([["1"] * 4] * 40)), ("None", None), ("3-d", np.zeros((2, 40, 4))),
                         ("2 frames", _track(2)), ("all missing", np.full((40, 4), NAN))]:
        add(f"tune boxes {label}", "boxes", lambda b=boxes: agents.tune(b, 1 / 30))
        add(f"smooth boxes {label}", "boxes", lambda b=boxes: agents.smooth(b, 1 / 30))
    for tau in (0.0, -1.0, NAN, "0.03", 10.0):
        add(f"tune tau {tau!r}", "tau", lambda t=tau: agents.tune(_track(), t))
    add("tune unknown backend", "backend", lambda: agents.tune(_track(), 1 / 30, backend="nope"))
    add("tune unknown pretrained", "pretrained", lambda: agents.tune(_track(), 1 / 30, pretrained="nope"))
    add("tune missing model folder", "model", lambda: agents.tune(_track(), 1 / 30, model="/nonexistent/run"))
    add("tune pretrained and model", "model", lambda: agents.tune(_track(), 1 / 30, pretrained="sim_ufir_cmn",
                                                                  model="/nonexistent/run"))

    # metrics
    add("iou shape mismatch", "b", lambda: metrics.iou(np.zeros((5, 4)), np.zeros((6, 4))))
    add("iou 3 columns", "a", lambda: metrics.iou(np.zeros((5, 3)), np.zeros((5, 3))))
    add("success_auc strings", "pred", lambda: metrics.success_auc(np.array([["a"] * 4]), np.zeros((1, 4))))
    add("success_curve thresholds nan", "thresholds",
        lambda: metrics.success_curve(_track(), _track(), thresholds=[0.1, NAN]))
    add("precision_score threshold -1", "threshold", lambda: metrics.precision_score(_track(), _track(), threshold=-1))
    add("rmse shape mismatch", "truth", lambda: metrics.rmse(np.zeros((5, 4)), np.zeros((4, 4))))
    return calls


CALLS = _make_calls()


def outcome(call: Call) -> str:
    """'ok' when ``call`` refuses as documented, else what happened instead (one line)."""
    start = time.perf_counter()
    try:
        call.run()
    except (ValueError, TypeError) as err:
        took = time.perf_counter() - start
        if took > SECONDS:
            return f"took {took:.1f} s"
        return "ok" if call.names in str(err) else f"{type(err).__name__} without {call.names!r}: {str(err)[:160]}"
    except Exception as err:  # noqa: BLE001  (any other exception is the finding)
        return f"{type(err).__name__}: {str(err)[:160]}"
    return "accepted"


@pytest.mark.parametrize("call", CALLS, ids=str)
def test_a_bad_call_raises_an_error_naming_the_argument(call: Call) -> None:
    assert outcome(call) == "ok"


if __name__ == "__main__":  # the arguments: substrings of call ids to leave out (e.g. "10^" on a machine short of memory)
    chosen = [call for call in CALLS if not any(part in call.id for part in sys.argv[1:])]
    bad = [(call.id, result) for call in chosen if (result := outcome(call)) != "ok"]
    for name, result in bad:
        print(f"{name}: {result}")
    print(f"{len(chosen) - len(bad)} of {len(chosen)} bad calls refused as documented")
    sys.exit(1 if bad else 0)
