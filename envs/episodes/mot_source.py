"""Episodes of real detection streams (``source="mot"``): one MOT15 ground-truth identity each, measured by the
public detections matched to it frame by frame (:mod:`bboxtune.envs.data.mot`).

An episode runs from the identity's first to its last matched detection: ``y`` holds the matched detection
(cx, cy, w, h) or a NaN row where none was matched (a detection gap, which the filter fills by prediction),
``truth`` the identity's ground-truth box or a NaN row where it has none (occlusion, a flag-0 row). τ = 1 / the
sequence's frame rate (7–30 fps). The pool is the identities of the config's ``split`` (by sequence, the OTB
rule: :func:`bboxtune.envs.data.mot.split`; with ``mot_holdout`` a leave-one-sequence-out fold,
:func:`bboxtune.envs.data.mot.holdout_split`) that keep at least ``min_frames`` frames; an unpinned draw picks one uniformly
from ``default_rng((noise_seed, 0))`` (the noise seed only chooses the identity: the stream itself is data). An
identity is named ``"<sequence>/<id>"`` (``options={"sequence": "KITTI-13/7"}`` pins it).

Lower frame rates (train split only, ``otb_speedup_max`` k_max > 1): an episode plays its identity at a frame
stride k drawn uniformly from [1, k_max] with ``default_rng((noise_seed, 4))`` (then an offset in [0, k)), i.e. at
fps / k with τ = k / fps — real detections, as a slower camera would have delivered them (MOT15 runs at 7–30 fps).
k is lowered so that at least :data:`STRIDED_MIN_FRAMES` frames (and ``min_frames``) and 2 detections remain; the
episode is then cut to its first and last detection again. The val and test splits play every frame.

Nominal σ (the fixed rule's) as the OTB sources': ``otb_sigma_v_rel`` / ``otb_sigma_w_rel`` × the median measured
box scale sqrt(w·h).

The mot part of ``source="mix"`` (``mix_weights`` (sim, otb, otb_tracker, mot)) is this source with the mix's
``split``, ``mot_root`` and ``otb_speedup_max`` (:func:`bboxtune.envs.episodes.config.mix_part`): the same episode for the same
noise seed, and never the simulated detection errors of the other parts.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import cast

import numpy as np

from bboxtune.envs.data import mot
from bboxtune.envs.data.boxes import xywh_to_cxcywh
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.episode import Episode, Source, rule_nominal
from bboxtune.envs.episodes.features import box_scale

STRIDED_MIN_FRAMES = 20  # frames an identity keeps at the least when played at a stride k > 1 (mot.MIN_FRAMES)


def identity_name(identity: mot.MOTIdentity) -> str:
    """``"<sequence>/<id>"``: how an identity is named in ``meta`` and pinned in ``options["sequence"]``."""
    return f"{identity.sequence}/{identity.identity}"


@lru_cache(maxsize=4)
def _identities(root: Path) -> tuple[mot.MOTIdentity, ...]:
    """Every identity of the MOT data at ``root`` (read and matched once per process and root: ~0.5 s)."""
    return tuple(mot.load_identities(root))


def detected_span(measured: np.ndarray) -> slice:
    """The rows of ``measured`` (T, 4) from the first to the last detection (an empty slice without one)."""
    detected = np.flatnonzero(np.isfinite(measured).all(axis=1))
    return slice(int(detected[0]), int(detected[-1]) + 1) if len(detected) else slice(0, 0)


def identity_episode(cfg: EnvConfig, identity: mot.MOTIdentity, noise_seed: int = 0, stride: int = 1,
                     offset: int = 0) -> Episode:
    """The episode of ``identity`` (module docstring) played at every ``stride``-th frame of its detected span from
    ``offset`` on, with the OTB sources' rule for its nominal parameters."""
    span = detected_span(identity.measured)
    frames = np.arange(span.start, span.stop)[offset::stride]
    cut = frames[detected_span(identity.measured[frames])]
    y = xywh_to_cxcywh(identity.measured[cut])
    truth = xywh_to_cxcywh(identity.truth[cut])
    tau = identity.tau * stride
    scale = cast(float, box_scale(y))  # of one track (T, 4)
    nominal = rule_nominal(cfg, cfg.otb_sigma_v_rel * scale, cfg.otb_sigma_w_rel * scale, tau)
    meta = {"sequence": identity_name(identity), "noise_seed": noise_seed, "tau": tau,
            "first_frame": identity.first_frame + int(cut[0]) if len(cut) else identity.first_frame}
    if stride > 1:
        meta.update(stride=stride, offset=offset)
    return Episode(truth=truth, y=y, tau=tau, nominal=nominal, meta=meta)


class MOTSource(Source):
    """MOT15 identities of one split (module docstring); ``sequences`` lists the pool's identity names.
    ``identities``: the identities to split (default: all of ``cfg.mot_root`` / $MOT_ROOT, read once per process)."""

    def __init__(self, cfg: EnvConfig, identities: tuple[mot.MOTIdentity, ...] | None = None) -> None:
        self.cfg = cfg
        if identities is None:
            identities = _identities(mot.resolve_root(cfg.mot_root).resolve())
        parts = mot.split(identities) if cfg.mot_holdout is None else mot.holdout_split(identities, cfg.mot_holdout)
        self._by_name = {identity_name(i): i for i in parts[cfg.split]}
        if not self._by_name:
            raise ValueError(f"no MOT identities in split {cfg.split!r} (sequences {sorted({i.sequence for i in identities})})")
        self._long_enough = tuple(self._by_name)

    @property
    def sequences(self) -> tuple[str, ...]:
        """The identities episodes are drawn from ("<sequence>/<id>", in the data's order)."""
        return self._long_enough

    def _length(self, name: str) -> int:
        span = detected_span(self._by_name[name].measured)
        return span.stop - span.start

    def max_frames(self) -> int:
        """The detected span of the pool's longest identity (frames)."""
        return max(self._length(name) for name in self._long_enough)

    def require_frames(self, n: int, why: str) -> None:
        """Leave the identities whose detected span is shorter than ``n`` frames out of the pool."""
        long_enough = tuple(name for name in self._by_name if self._length(name) >= n)
        if not long_enough:
            raise ValueError(f"no MOT identity of split {self.cfg.split!r} has the {n} frames {why} needs")
        self._long_enough = long_enough
        self.min_frames = n

    def draw(self, sequence: str | None, noise_seed: int) -> Episode:
        if sequence is None:
            rng = np.random.default_rng((noise_seed, 0))
            sequence = self._long_enough[int(rng.integers(len(self._long_enough)))]
        elif sequence not in self._by_name:
            raise ValueError(f"options['sequence']={sequence!r} is not a MOT identity of split {self.cfg.split!r}; "
                             f"allowed: '<sequence>/<id>' of env.unwrapped.source.sequences")
        elif self._length(sequence) < self.min_frames:
            raise ValueError(f"options['sequence']={sequence!r} has {self._length(sequence)} frames; this env needs "
                             f"at least {self.min_frames}")
        identity = self._by_name[sequence]
        if self.cfg.otb_speedup_max > 1 and self.cfg.split == "train":
            return self._strided(identity, noise_seed)
        return identity_episode(self.cfg, identity, noise_seed)

    def _strided(self, identity: mot.MOTIdentity, noise_seed: int) -> Episode:
        """The identity at a drawn frame stride (module docstring), lowered until enough frames remain."""
        rng = np.random.default_rng((noise_seed, 4))
        stride = int(rng.integers(1, self.cfg.otb_speedup_max + 1))
        offset = int(rng.integers(stride))
        while stride > 1:
            episode = identity_episode(self.cfg, identity, noise_seed, stride, offset % stride)
            if len(episode.y) >= max(STRIDED_MIN_FRAMES, self.min_frames) and np.isfinite(episode.y).all(axis=1).sum() >= 2:
                return episode
            stride -= 1
        return identity_episode(self.cfg, identity, noise_seed)
