"""Episodes whose measurements come from a real detector run on synthetic video (``source="video"``).

A video is identified by its split and index: the sequence name ``"<split>-<index>"`` (e.g.
``"train-00007"``); its generator seed is ``SPLIT_OFFSET[split] + index``, so the train, val and test videos
never overlap. Each split holds ``video_pool`` videos; an episode without a pinned sequence picks one from its
noise seed. The detector is deterministic, so an episode is a pure function of (sequence, noise seed) — the
noise seed only chooses the video.

Cache: rendering and detecting cost one to a few seconds per 200-frame video (SIFT is the slowest), so every
(video, detector) result is computed once and kept in memory for the life of the process (a module-level
dict, about 100 bytes per frame), and — when ``video_cache`` names a folder —
also on disk as ``<video_cache>/<detector>/<seed>-<key>.npz`` (truth and detections, xywh). ``key`` is the
first 16 hex digits of the SHA-256 of the JSON of everything the result depends on (generator version,
scenario ranges, seed, detector name and parameters, frame count, frame size), so changing any of them never
reads a stale file (a code change that alters the output without changing a parameter must bump
:data:`GENERATOR_VERSION`). Files are written atomically (temporary name + ``os.replace``), so parallel workers can
share the folder. Delete the folder to clear it.

Nominal σ (the fixed rule's): σ_v = ``sigma_v_rel`` × scale and σ_w = ``sigma_w_rel`` × scale, scale = median
sqrt(w·h) of the measured boxes, with per-detector defaults :data:`NOMINAL_REL` calibrated once on training
videos (:func:`calibrate_nominal`; the test videos were never used).
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any, cast

import numpy as np

from bboxtune.envs.data.atomic_files import atomic_write
from bboxtune.envs.data.boxes import xywh_to_cxcywh
from bboxtune.envs.episodes.actions import Nominal
from bboxtune.envs.episodes.episode import Episode, Source
from bboxtune.envs.episodes.features import box_scale
from bboxtune.envs.video.detectors import DETECTORS, detect_video, make_detector
from bboxtune.envs.video.synthetic import VideoRanges, synthetic_video

GENERATOR_VERSION = 2  # bump when the generator or a detector changes its output (2: re-detection, template scales)
SPLIT_OFFSET = {"train": 0, "val": 1_000_000, "test": 2_000_000}  # generator seed = offset + index

# (σ_v / scale, σ_w / scale [1/s²]) per detector: medians over 24 training videos of the robust
# (MAD) centre error and the RMS true acceleration, from calibrate_nominal().
NOMINAL_REL: dict[str, tuple[float, float]] = {
    "bgsub": (0.277, 13.1), "mog2": (0.0398, 13.1), "template": (0.0123, 15.8),
    "sift": (0.00852, 14.0), "orb": (0.0194, 13.7), "regions": (0.00622, 14.9),
}


@dataclass(frozen=True)
class VideoSettings:
    """Settings of the video source; the env config fields of the same names override the defaults."""

    detector: str = "template"  # one of bboxtune.envs.video.detectors.DETECTORS
    video_pool: int = 64  # distinct videos per split
    video_cache: str | None = None  # folder of the on-disk cache; None: memory only
    video_size: tuple[int, int] = (320, 240)  # px, frame width and height
    video_sigma_v_rel: float | None = None  # nominal σ_v / box scale; None: NOMINAL_REL[detector][0]
    video_sigma_w_rel: float | None = None  # 1/s², nominal σ_w / box scale; None: NOMINAL_REL[detector][1]

    def __post_init__(self) -> None:
        if self.detector not in DETECTORS:
            raise ValueError(f"detector={self.detector!r}; allowed: {DETECTORS}")
        if not 1 <= int(self.video_pool) <= 1_000_000:
            raise ValueError(f"video_pool={self.video_pool!r}; allowed: integers 1..1000000")
        w, h = self.video_size
        if not (64 <= w <= 4096 and 64 <= h <= 4096):
            raise ValueError(f"video_size={self.video_size!r}; allowed: width and height in [64, 4096] px")
        for name in ("video_sigma_v_rel", "video_sigma_w_rel"):
            value = getattr(self, name)
            if value is not None and not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name}={value!r}; allowed: None or a finite value > 0")

    @classmethod
    def from_config(cls, cfg: Any) -> VideoSettings:
        """Defaults overridden by the attributes of ``cfg`` (an EnvConfig) that have these names."""
        return cls(**{f.name: getattr(cfg, f.name) for f in fields(cls) if hasattr(cfg, f.name)})

    @property
    def nominal_rel(self) -> tuple[float, float]:
        v, w = NOMINAL_REL[self.detector]
        return (self.video_sigma_v_rel or v, self.video_sigma_w_rel or w)


_MEMORY: dict[str, dict[str, np.ndarray]] = {}


def detected_video(seed: int, detector: str, n_frames: int, size: tuple[int, int] = (320, 240),
                   cache: str | os.PathLike | None = None) -> dict[str, np.ndarray]:
    """Render video ``seed`` (:func:`bboxtune.envs.video.synthetic.synthetic_video`) and run ``detector`` on it.

    Returns ``{"truth": (T, 4), "y": (T, 4)}`` xywh px (NaN rows: no detection), ``"tau"`` () s and
    ``"camera"`` (T, 2) px (true camera offset, for analysis); cached as described in the module docstring."""
    ranges = VideoRanges(width=int(size[0]), height=int(size[1]), n_frames=int(n_frames))
    det = make_detector(detector)
    key_src = json.dumps({"version": GENERATOR_VERSION, "ranges": asdict(ranges), "seed": int(seed),
                          "detector": detector, "params": det.params()}, sort_keys=True)
    key = hashlib.sha256(key_src.encode()).hexdigest()[:16]
    if key in _MEMORY:
        return _MEMORY[key]
    path = Path(cache) / detector / f"{seed}-{key}.npz" if cache is not None else None
    if path is not None and path.is_file():
        with np.load(path) as data:
            result = {k: data[k] for k in data.files}
    else:
        video = synthetic_video(int(seed), ranges)
        y = detect_video(det, video, video.boxes[0])
        result = {"truth": video.boxes, "y": y, "tau": np.float64(video.tau), "camera": video.camera}
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write(path, lambda tmp: np.savez(tmp, **result))
    _MEMORY[key] = result
    return result


def parse_sequence(name: str) -> tuple[str, int]:
    """``"test-00012"`` → ("test", 12); ValueError for anything else."""
    split, _, index = str(name).partition("-")
    if split not in SPLIT_OFFSET or not index.isdigit():
        raise ValueError(f"sequence={name!r}; allowed: '<split>-<index>' with split in {tuple(SPLIT_OFFSET)}")
    return split, int(index)


class VideoSource(Source):
    """Episodes from synthetic videos of one split measured by one detector (an :class:`bboxtune.envs.episodes.sources.Source`:
    ``draw(sequence, noise_seed) -> Episode``; boxes cx, cy, w, h)."""

    n_frames: int  # every video's length (cfg.track_length): always fixed here

    def __init__(self, cfg: Any, settings: VideoSettings | None = None) -> None:
        self.cfg = cfg
        self.settings = settings or VideoSettings.from_config(cfg)
        self.split = getattr(cfg, "split", "train")
        self.n_frames = int(getattr(cfg, "track_length", 200))
        self.horizon_max = int(getattr(cfg, "horizon_max", 400))
        self.nominal_psi = float(getattr(cfg, "nominal_psi", 0.0))
        self.names = tuple(f"{self.split}-{i:05d}" for i in range(self.settings.video_pool))

    def draw(self, sequence: str | None, noise_seed: int) -> Episode:
        if sequence is None:
            sequence = self.names[int(np.random.default_rng((noise_seed, 0)).integers(len(self.names)))]
        split, index = parse_sequence(sequence)
        if split != self.split or index >= self.settings.video_pool:
            raise ValueError(f"options['sequence']={sequence!r} is not one of this source's videos "
                             f"({self.names[0]} … {self.names[-1]})")
        s = self.settings
        data = detected_video(SPLIT_OFFSET[split] + index, s.detector, self.n_frames, s.video_size, s.video_cache)
        return self.episode(data, meta={"sequence": sequence, "noise_seed": noise_seed})

    def episode(self, data: dict[str, np.ndarray], meta: dict[str, Any]) -> Episode:
        """The Episode of a :func:`detected_video` result (nominal σ from the measured box scale)."""
        y = xywh_to_cxcywh(data["y"])
        tau = float(data["tau"])
        rel_v, rel_w = self.settings.nominal_rel
        scale = cast(float, box_scale(y))  # of one track (T, 4)
        sigma_v, sigma_w = rel_v * scale, rel_w * scale
        nominal = Nominal.of_rule(sigma_v, sigma_w, tau, self.nominal_psi, self.horizon_max)
        meta = {**meta, "detector": self.settings.detector, "tau": tau,
                "n_missing": int(np.isnan(y).any(axis=1).sum())}
        return Episode(truth=xywh_to_cxcywh(data["truth"]), y=y, tau=tau, nominal=nominal, meta=meta)


def calibrate_nominal(detector: str, n_videos: int = 24, n_frames: int = 200,
                      cache: str | os.PathLike | None = None) -> tuple[float, float]:
    """(σ_v / scale, σ_w / scale) medians over the first ``n_videos`` training videos: σ_v from the median
    absolute centre error of the detections (× 1.4826, robust to lost frames), σ_w from the RMS second
    difference of the true centres / τ²."""
    rel_v, rel_w = [], []
    for index in range(n_videos):
        data = detected_video(SPLIT_OFFSET["train"] + index, detector, n_frames, cache=cache)
        truth, y, tau = xywh_to_cxcywh(data["truth"]), xywh_to_cxcywh(data["y"]), float(data["tau"])
        scale = box_scale(y)
        err = np.abs(y[:, :2] - truth[:, :2])
        rel_v.append(1.4826 * np.nanmedian(err) / scale)
        rel_w.append(np.sqrt(np.mean(np.diff(truth[:, :2], n=2, axis=0) ** 2)) / tau**2 / scale)
    return float(np.median(rel_v)), float(np.median(rel_w))
