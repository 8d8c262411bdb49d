"""Learned tuning for library use: the filter parameters a trained tuner chooses for a track, and the track
smoothed with them.

    from bboxtune import agents
    params = agents.tune(boxes, tau=1 / 30)      # e.g. {"psi": 0.42, "horizon": 7}: the default pretrained tuner
    smoothed = agents.smooth(boxes, tau=1 / 30)  # (T, 4) xywh: filtered with them, or as given where the gate leaves it

    from bboxtune.agents.smoothing.tuner import Tuner  # a scripts/train.py run, loaded once for many tracks
    tuner = Tuner.from_run("runs/ppo_ufir_cmn_sim_s0")
    params, smoothed = tuner.tune(boxes, 1 / 30), tuner.smooth(boxes, 1 / 30)

Conventions: ``boxes`` is (T, 4) x, y (top-left corner), w, h in px (OTB's xywh) with w, h > 0 and \\|x\\|, \\|y\\|,
w, h <= 1e7 px (:data:`bboxtune.envs.data.boxes.MAX_COORD`); a row of NaN is a missing frame (a partly NaN row,
±inf, w, h <= 0 or a larger value is an error). ``tau`` is the frame interval in s, in
[1e-3, 1] (the envs' range; 1/30 for 30 fps video). A track needs at least :data:`MIN_FRAMES` frames of which
at least :data:`MIN_MEASURED` are measured. Errors name the argument (ValueError for a value, TypeError for a
type). The tuner sees the measurements only, never a ground truth.

Which tuner: ``model=RUN_DIR`` (a ``scripts/train.py`` run of ``bboxtune/FilterTune-v0``; its final model), else
``pretrained=NAME`` (:mod:`bboxtune.agents.smoothing.pretrained`), else the pretrained tracker-output tuner of ``backend``
(``otb_tracker_<backend>``; :data:`DEFAULT_PRETRAINED` when ``backend`` is None). ``backend`` given with a tuner
of another back end is an error. Pretrained tuners are loaded once per process; for many tracks with a run
directory, load it once with :meth:`Tuner.from_run` and call its methods.

The observation is computed by the env's own code for an episode of the tuner's config
(:meth:`Tuner.observe`): the source's fixed rule (:func:`rule_nominal`: its nominal σ and N_opt), that rule's
filter run (:func:`bboxtune.envs.episodes.scoring.run_track`), then
:func:`bboxtune.envs.episodes.features.measurement_features` — so it equals
the env's reset observation on the same measurements (tested), and the parameters equal what ``env.step``
applies for the policy's action. A ``bytetrack_kf`` tuner whose rule scales with the box (OTB and MOT sources, e.g.
``mot15_det``) runs these steps as one compiled call (:mod:`bboxtune.agents.smoothing.observe_kernels`, bit for bit).
Smoothed boxes are the back end's position estimates; frames before the
first measured one have no estimate (NaN rows), later missing frames are predicted.

Back-end settings outside the tuner's action (``backend_params`` in its ``config.yml``, a mapping of parameter
names to numbers, e.g. ``mot15_det``'s bytetrack_kf gap policy ``gap_velocity_decay`` / ``gap_size_decay``:
:mod:`bboxtune.filters.gap_output`) apply wherever :meth:`Tuner.smooth` filters a track, the same for every track;
they change neither the observation nor the parameters :meth:`Tuner.tune` returns (so neither a tracker's re-tuned
filter nor the env's reward, which score the tuner's parameters alone). :meth:`Tuner.with_backend_params` replaces them.

A gated tuner (:mod:`bboxtune.agents.evaluation.gate`: a ``gate.json`` in the tuner's folder, read when it is loaded, or
``Tuner.with_gate(FILE)`` for a file that ``compare.py --gate`` wrote) leaves a track alone where its gate stays
closed (:meth:`Tuner.leaves_alone`): :meth:`Tuner.smooth` then returns the boxes as given, missing frames included.
:meth:`Tuner.tune` still returns the parameters the model would set.

``import bboxtune.agents`` imports this module (for :func:`bboxtune.agents.tune` / :func:`bboxtune.agents.smooth`);
stable-baselines3 and torch are imported when a tuner is first loaded, so that every ``bboxtune.agents`` import (e.g.
the scripts' :mod:`bboxtune.agents.cli`) stays light.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import cache, cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np
from numpy.typing import ArrayLike

from bboxtune import filters
from bboxtune.agents.policies.gate_file import GATE_FILE, Gate, read_gate
from bboxtune.agents.smoothing import observe_kernels, pretrained
from bboxtune.envs.data.boxes import COORD_RULE, beyond_max_coord, cxcywh_to_xywh, xywh_to_cxcywh
from bboxtune.envs.episodes.actions import ACCEPTS, K_AXIS, ActionMap, Nominal
from bboxtune.envs.episodes.config import EnvConfig, check_real
from bboxtune.envs.episodes.episode import Episode
from bboxtune.envs.episodes.episode import rule_nominal as source_nominal  # the sources' own rule for given σ
from bboxtune.envs.episodes.features import box_scale, measurement_features
from bboxtune.envs.episodes.scoring import box_model, run_positions, run_track
from bboxtune.envs.episodes.sources import SimSource
from bboxtune.envs.episodes.video_source import VideoSettings
from bboxtune.envs.track_env import TrackEnv
from bboxtune.filters import jit
from bboxtune.filters.bytetrack_kf import GAP_DECAYS, SIZE_MIN, ByteTrackKF
from bboxtune.filters.validation import SIGMA_RANGE
from bboxtune.filters.validation import TAU_RANGE as FILTER_TAU_RANGE

if TYPE_CHECKING:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from bboxtune.agents.training.runs import SB3Policy

ONE_STEP_ENV = "bboxtune/FilterTune-v0"
DEFAULT_PRETRAINED = "otb_tracker_kf_cmn"  # chosen on the val split (docs/smoothing.md)
TAU_RANGE = (1e-3, 1.0)  # s, the envs' range of frame intervals
MIN_FRAMES = 8  # the envs' shortest track
MIN_MEASURED = 2  # a box scale and one difference
# env settings that EnvConfig refuses with source "sim"
SOURCE_ONLY = ("trackers", "mix_weights", "otb_speedup_max", "mot_root", "mot_holdout")
BACKEND_PARAMS = "backend_params"  # config.yml: back-end settings outside the tuner's action (module docstring)
STD_WEIGHTS = tuple(k for k in ByteTrackKF.PER_TRACK if k not in GAP_DECAYS)  # bytetrack_kf's noise weights, in order


def check_boxes(boxes: ArrayLike, name: str = "boxes") -> np.ndarray:
    """``boxes`` as float (T, 4) xywh after the checks of the module docstring (errors name ``name``)."""
    try:
        arr = np.asarray(boxes)
    except (ValueError, TypeError) as err:
        raise ValueError(f"{name} is not an array of numbers ({err})") from None
    if arr.dtype.kind not in "iuf":
        raise TypeError(f"{name} has dtype {arr.dtype}; allowed: real numbers, (T, 4) x, y, w, h in px")
    arr = arr.astype(np.float64)
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise ValueError(f"{name} has shape {arr.shape}; allowed: (T, 4) x, y, w, h in px")
    missing = np.isnan(arr)
    rows = missing.all(axis=1)
    if (missing.any(axis=1) & ~rows).any():
        i = int(np.argmax(missing.any(axis=1) & ~rows))
        raise ValueError(f"{name}[{i}] = {arr[i].tolist()} is partly NaN; a missing frame is a row of NaN")
    bad = ~rows & (~np.isfinite(arr).all(axis=1) | (arr[:, 2:] <= 0).any(axis=1) | beyond_max_coord(arr))
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{name}[{i}] = {arr[i].tolist()}; allowed: finite x, y and w, h > 0 with {COORD_RULE}, "
                         "or a row of NaN")
    if len(arr) < MIN_FRAMES or int((~rows).sum()) < MIN_MEASURED:
        raise ValueError(f"{name} has {len(arr)} frames, {int((~rows).sum())} of them measured; a track needs at "
                         f"least {MIN_FRAMES} frames and {MIN_MEASURED} measured ones")
    return arr


def check_tau(tau: Any) -> float:
    """``tau`` (s) as a float in :data:`TAU_RANGE` (TypeError / ValueError naming ``tau``)."""
    return check_real("tau", tau, *TAU_RANGE)


def rule_nominal(cfg: EnvConfig, y: np.ndarray, tau: float) -> Nominal:
    """The fixed rule's parameters that the source of ``cfg`` gives a track of measurements ``y`` (T, 4)
    (cx, cy, w, h px; NaN = missing) at frame interval ``tau``: ``sim`` its nominal σ (the centres of the
    config's σ ranges; with ``sim_noise="box"`` the OTB sources' rule below, as its episodes have it); ``video``
    the detector's relative σ × the measured box scale; ``otb``, ``otb_tracker``, ``mot`` (and a mixed source,
    whose real-data episodes use it) ``otb_sigma_v_rel`` / ``otb_sigma_w_rel`` × the measured box scale; then
    N = N_opt(σ_v, σ_w, τ) within [K, horizon_max] and ψ = ``nominal_psi``."""
    if cfg.source == "sim" and cfg.sim_noise == "absolute":
        sim = SimSource(cfg)
        return source_nominal(cfg, sim.sigma_v_nominal, sim.sigma_w_nominal, tau)
    if cfg.source == "video":
        rel_v, rel_w = VideoSettings.from_config(cfg).nominal_rel
    else:
        rel_v, rel_w = cfg.otb_sigma_v_rel, cfg.otb_sigma_w_rel
    scale = cast(float, box_scale(y))  # one track: a float
    return source_nominal(cfg, rel_v * scale, rel_w * scale, tau)


def spaces_venv(cfg: dict[str, Any], where: Path) -> DummyVecEnv:
    """The run's env with the ``sim`` source (less the settings only other sources take, :data:`SOURCE_ONLY`) in a
    DummyVecEnv: the same spaces and action map as the config's env (they depend on the back end and the action
    settings, not on where episodes come from) without needing its data set (OTB, videos); :class:`RunError`
    naming ``where`` if it cannot be built."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    from bboxtune.agents.training.run_files import RunError
    from bboxtune.agents.training.runs import ENV_ERRORS

    kwargs = {k: v for k, v in cfg["env_kwargs"].items() if k not in SOURCE_ONLY} | {"source": "sim"}
    try:
        return DummyVecEnv([lambda: gym.make(cfg["env_id"], **kwargs)])
    except ENV_ERRORS as err:
        raise RunError(f"{where}: env {cfg['env_id']} with env_kwargs {cfg['env_kwargs']} cannot be built ({err})") from None


@dataclass(frozen=True)
class Observation:
    """What the tuner sees of one track: the env's observation, the rule's parameters, the measurements."""

    obs: np.ndarray  # (n_features,) float32, bboxtune.envs.episodes.features.FEATURE_NAMES
    nominal: Nominal  # the fixed rule's parameters (what the action map scales)
    y: np.ndarray  # (T, 4) cx, cy, w, h px, NaN rows missing
    tau: float  # s


@dataclass(frozen=True)
class Tuner:
    """A trained one-step tuner with its env config: chooses filter parameters per track from measurements."""

    name: str  # the pretrained name or the run directory
    policy: SB3Policy
    config: EnvConfig  # the env it was trained on (source, back end, action settings)
    action_map: ActionMap
    gate: Gate | None = None  # where it stays closed the track is left alone (bboxtune.agents.policies.gate_file)
    backend_params: Mapping[str, float] = field(default_factory=dict)  # fixed back-end settings (module docstring)

    @classmethod
    def from_run(cls, run_dir: str | os.PathLike, name: str | None = None) -> Tuner:
        """The final model of a ``scripts/train.py`` run (or a pretrained folder) of ``bboxtune/FilterTune-v0``,
        loaded without unpickling and without the run's data set; :class:`RunError` naming the file at fault."""
        from bboxtune.agents.training.run_files import RunError
        from bboxtune.agents.training.runs import CONFIG, SB3Policy, load_config

        run_dir = Path(run_dir)
        cfg = load_config(run_dir)
        if cfg["env_id"] != ONE_STEP_ENV:
            raise RunError(f"{run_dir / CONFIG}: env_id {cfg['env_id']}; a tuner chooses one parameter set per track "
                           f"({ONE_STEP_ENV})")
        venv = spaces_venv(cfg, run_dir / CONFIG)
        env = cast(TrackEnv, venv.envs[0].unwrapped)
        config = EnvConfig.from_kwargs(**cfg["env_kwargs"])  # constructing a config reads no data
        policy = SB3Policy.load(run_dir, "final", venv=venv)
        tuner = cls(name=name or str(run_dir), policy=policy, config=config, action_map=env.action_map)
        try:
            tuner = tuner.with_backend_params(cfg.get(BACKEND_PARAMS, {}))
        except (ValueError, TypeError) as err:
            raise RunError(f"{run_dir / CONFIG}: {BACKEND_PARAMS}: {err}") from None
        return tuner.with_gate(run_dir / GATE_FILE) if (run_dir / GATE_FILE).exists() else tuner

    def with_backend_params(self, params: Mapping[str, Any]) -> Tuner:
        """This tuner with the back-end settings ``params`` (``{name: number}``, names of the back end's parameters
        that the tuner does not set; ValueError / TypeError naming the parameter) instead of its own."""
        if not isinstance(params, Mapping):
            raise TypeError(f"{params!r} is a {type(params).__name__}; allowed: a mapping of parameter names to numbers")
        outside = sorted(set(filters.filter_class(self.backend).DEFAULTS) - set(ACCEPTS[self.backend]))
        for name, value in params.items():
            if name not in outside:
                raise ValueError(f"{name!r} is not a setting of back end {self.backend} outside the tuner's action; "
                                 f"allowed: {', '.join(outside) or 'none'}")
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise TypeError(f"{name}={value!r}; allowed: a number")
        filters.make(self.backend, box_model(1.0), **params)  # each value within its range
        return replace(self, backend_params={k: float(v) for k, v in params.items()})

    def with_gate(self, path: str | os.PathLike) -> Tuner:
        """This tuner gated by the gate file ``path`` (:mod:`bboxtune.agents.policies.gate_file`; ValueError naming the file)."""
        n_features = cast("tuple[int, ...]", self.policy.model.observation_space.shape)[0]
        return replace(self, gate=read_gate(path, n_features))

    def leaves_alone(self, seen: Observation) -> bool:
        """Whether the gate (if any) leaves this track as measured."""
        return self.gate is not None and not bool(self.gate.opens(seen.obs[None])[0])

    @property
    def backend(self) -> str:
        return self.config.backend

    @property
    def parameters(self) -> tuple[str, ...]:
        """The back end's parameters this tuner sets (the keys of :meth:`params`)."""
        return ACCEPTS[self.backend]

    def observe(self, boxes: ArrayLike, tau: Any) -> Observation:
        """The observation of the track ``boxes`` (T, 4) xywh at frame interval ``tau`` (s), as the env of the
        tuner's config computes it at reset (module docstring)."""
        return self._observe(check_boxes(boxes), check_tau(tau))

    def _observe(self, xywh: np.ndarray, tau: float) -> Observation:
        """:meth:`observe` of a track already checked (:func:`check_boxes`, :func:`check_tau`): by one compiled call
        where the tuner has one (:attr:`_compiled_rule`), else by :meth:`_observe_steps`."""
        rule = self._compiled_rule
        if rule is not None and jit.enabled():
            rel_v, rel_w, stds = rule
            y, obs, sigma_v, sigma_w, horizon, valid = observe_kernels.box_observation(
                xywh, tau, rel_v, rel_w, stds, SIZE_MIN, (K_AXIS, self.config.horizon_max), SIGMA_RANGE, FILTER_TAU_RANGE)
            if valid:
                nominal = Nominal(sigma_w=sigma_w, sigma_v=sigma_v, psi=self.config.nominal_psi, horizon=horizon)
                return Observation(obs=obs.astype(np.float32), nominal=nominal, y=y, tau=tau)
        return self._observe_steps(xywh, tau)

    @cached_property
    def _compiled_rule(self) -> tuple[float, float, np.ndarray] | None:
        """For a ``bytetrack_kf`` tuner whose rule scales with the box (:func:`rule_nominal`'s OTB / MOT branch):
        the rule's relative σ_v, σ_w and its filter's five noise weights (5, 1), the arguments of
        :func:`bboxtune.agents.smoothing.observe_kernels.box_observation`; None for every other tuner (and for one
        trained on the ``"msd"`` feature set, which that kernel does not compute)."""
        cfg = self.config
        if self.backend != "bytetrack_kf" or cfg.source in ("sim", "video") or cfg.features != "base":
            return None
        nominal = Nominal(sigma_w=1.0, sigma_v=1.0, psi=cfg.nominal_psi, horizon=K_AXIS)  # the weights only
        weights = filters.filter_class(self.backend).DEFAULTS | {k: getattr(nominal, k) for k in ACCEPTS[self.backend]}
        stds = np.array([[weights[k]] for k in STD_WEIGHTS], dtype=float)
        return cfg.otb_sigma_v_rel, cfg.otb_sigma_w_rel, stds

    def _observe_steps(self, xywh: np.ndarray, tau: float) -> Observation:
        """:meth:`_observe` step by step (module docstring)."""
        y = xywh_to_cxcywh(xywh)
        nominal = rule_nominal(self.config, y, tau)
        track = Episode(truth=np.full_like(y, np.nan), y=y, tau=tau, nominal=nominal)  # no ground truth: none is used
        rule = run_track(self.backend, y, tau, TrackEnv.rule_params(track))
        obs = measurement_features(y, tau, nominal.sigma_v, nominal.sigma_w, rule, msd=self.config.features == "msd")
        return Observation(obs=obs, nominal=nominal, y=y, tau=tau)

    def action(self, seen: Observation) -> np.ndarray:
        """The policy's action (d,) in [-1, 1] for an observation."""
        return self.policy.predict(seen.obs[None])[0]

    def params(self, seen: Observation) -> dict[str, float | int]:
        """The back end's parameters for an observed track (``horizon`` an int, the others floats), as ``env.step``
        would apply them for the policy's action."""
        params = self.action_map.to_params(self.action(seen), seen.nominal)
        return {k: int(params[k][0]) if k == "horizon" else float(params[k][0]) for k in ACCEPTS[self.backend]}

    def tune(self, boxes: ArrayLike, tau: Any) -> dict[str, float | int]:
        """:meth:`params` of the track ``boxes`` at frame interval ``tau``."""
        return self.tune_checked(check_boxes(boxes), check_tau(tau))

    def tune_checked(self, xywh: np.ndarray, tau: float) -> dict[str, float | int]:
        """:meth:`tune` of a track that already passed :func:`check_boxes` (float (T, 4) xywh px) and :func:`check_tau`,
        without checking it again: for a caller that checked it itself (a tracker re-tuning its tracks from their
        histories of checked detections, many times a second)."""
        return self.params(self._observe(xywh, tau))

    def smooth(self, boxes: ArrayLike, tau: Any, params: dict[str, float | int] | None = None) -> np.ndarray:
        """The track filtered by the back end with ``params`` (default: :meth:`tune`'s) and the tuner's
        ``backend_params``, (T, 4) xywh px; NaN rows where there is no estimate (before the first measured frame).
        Without ``params``, a track the gate leaves alone is returned as given."""
        xywh, tau = check_boxes(boxes), check_tau(tau)  # checked and converted once, for every path below
        if params is None:
            seen = self._observe(xywh, tau)
            if self.leaves_alone(seen):
                return xywh.copy()
            params, y = self.params(seen), seen.y
        else:
            if set(params) != set(ACCEPTS[self.backend]):
                raise ValueError(f"params has keys {sorted(params)}; back end {self.backend} takes "
                                 f"{ACCEPTS[self.backend]}")
            y = xywh_to_cxcywh(xywh)
        est = run_positions(self.backend, y, tau, {k: np.array([v]) for k, v in params.items()}, self.backend_params)[0]
        return cxcywh_to_xywh(est)


def load_pretrained(name: str) -> Tuner:
    """The pretrained tuner ``name`` (:mod:`bboxtune.agents.smoothing.pretrained`; ValueError listing the available
    ones or naming a missing file), cached per process and folder (the files are package data)."""
    return _load_folder(name, pretrained.folder(name))


@cache
def _load_folder(name: str, path: Path) -> Tuner:
    return Tuner.from_run(path, name=name)


def load_tuner(backend: str | None = None, pretrained_name: str | None = None,
               model: str | os.PathLike | None = None) -> Tuner:
    """The tuner :func:`tune` uses for these arguments (module docstring; ValueError naming the argument)."""
    if model is not None and pretrained_name is not None:
        raise ValueError("pass model= (a run directory) or pretrained= (a name), not both")
    if model is not None:
        if not Path(model).is_dir():
            raise ValueError(f"model={str(model)!r} is not a folder; allowed: a scripts/train.py run directory")
        tuner = Tuner.from_run(model)
    elif pretrained_name is None and backend is not None and f"otb_tracker_{backend}" not in pretrained.available():
        tuned = sorted(name.removeprefix("otb_tracker_") for name in pretrained.available() if name.startswith("otb_tracker_"))
        raise ValueError(f"backend={backend!r} has no pretrained tracker-output tuner; allowed: {', '.join(tuned)} "
                         "(or pass pretrained= / model=)")
    else:
        tuner = load_pretrained(pretrained_name or (f"otb_tracker_{backend}" if backend else DEFAULT_PRETRAINED))
    if backend is not None and backend != tuner.backend:
        raise ValueError(f"backend={backend!r}, but the tuner {tuner.name} tunes {tuner.backend!r}")
    return tuner


def tune(boxes: ArrayLike, tau: Any, backend: str | None = None, pretrained: str | None = None,
         model: str | os.PathLike | None = None) -> dict[str, float | int]:
    """Filter parameters for the track ``boxes`` (T, 4) xywh px (NaN rows missing) at frame interval ``tau`` (s),
    chosen by a trained tuner from the measurements: ``{name: value}`` for every parameter the back end takes
    (e.g. ufir_cmn: ``psi``, ``horizon``; bytetrack_kf: its two std weights and ``std_aspect_measurement``, stock
    unless tuned). Which tuner: module docstring."""
    return load_tuner(backend, pretrained, model).tune(boxes, tau)


def smooth(boxes: ArrayLike, tau: Any, backend: str | None = None, pretrained: str | None = None,
           model: str | os.PathLike | None = None) -> np.ndarray:
    """The track ``boxes`` (T, 4) xywh px smoothed by the back end with :func:`tune`'s parameters: (T, 4) xywh px,
    NaN rows before the first measured frame."""
    return load_tuner(backend, pretrained, model).smooth(boxes, tau)
