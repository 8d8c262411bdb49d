"""Synthetic videos with exactly known boxes: a textured object over a textured background.

The object (a rigid textured rectangle of one dominant hue) moves with constant velocity plus manoeuvres
(intervals of constant acceleration at Poisson onsets) and white acceleration noise, bounces off the frame
borders, changes scale smoothly, wobbles (in-plane rotation) and deforms (w and h scaled oppositely) —
the appearance changes that make real detectors jitter. Optional: a moving camera (slow pan + hand shake),
Gaussian blur, global illumination change, a static occluder on the object's path, sensor noise.

Conventions:

* Frames are BGR uint8 (H, W, 3); frame ``t`` (0-based) is shown at time ``t τ``, τ = 1 / ``fps``.
* Boxes are xywh, 0-based, continuous areas: pixel (i, j) covers [i, i + 1) × [j, j + 1), a box covers
  [x, x + w) × [y, y + h). The ground truth is the axis-aligned bounding box of the rendered (rotated,
  scaled) object rectangle, sub-pixel exact, also while the object is occluded.
* ``camera`` (T, 2) is the camera offset in px (frame 0 = 0): a scene point at world position ``p`` is seen
  at image position ``p − camera[t]``. Object image position = world position − camera.
* Everything is a pure function of ``(scenario, seed)``; ``frame(t)`` gives frame ``t`` alone (random
  access), so long videos never need to be held in memory.

>>> video = render(VideoScenario(width=64, height=48, n_frames=5, object_size=(16.0, 12.0)), seed=1)
>>> video.frame(0).shape, video.boxes.shape, video.camera.shape
((48, 64, 3), (5, 4), (5, 2))
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import cv2
import numpy as np

_OBJECT_HUE_GAP = 25  # OpenCV hue units (0–180): background clutter stays this far from the object's hue


@dataclass(frozen=True)
class VideoScenario:
    """One synthetic video's settings (units in comments)."""

    width: int = 320  # px
    height: int = 240  # px
    n_frames: int = 200  # T
    fps: float = 30.0  # frames/s (τ = 1/fps)
    object_size: tuple[float, float] = (48.0, 36.0)  # px, object w, h at scale 1
    speed: float = 60.0  # px/s, initial speed (random direction)
    max_speed: float = 240.0  # px/s, speed cap
    sigma_w: float = 10.0  # px/s², white acceleration noise std per axis
    manoeuvre_rate: float = 0.5  # 1/s, Poisson rate of manoeuvre onsets
    manoeuvre_accel: float = 150.0  # px/s², std per axis of a manoeuvre's constant acceleration
    manoeuvre_duration: tuple[float, float] = (0.3, 1.0)  # s, uniform
    scale_change: float = 0.0  # max |log scale| of the smooth size oscillation (0 = rigid size)
    rotation: float = 0.0  # deg, amplitude of the in-plane wobble (0.3–1.5 Hz)
    deformation: float = 0.0  # amplitude of log(w-scale) = −log(h-scale) of the non-rigid oscillation (0.5–2 Hz)
    camera_motion: float = 0.0  # px, pan amplitude per axis (shake: a quarter of it); 0 = static camera
    blur: float = 0.0  # px, Gaussian blur σ of every frame (0 = sharp)
    illumination: float = 0.0  # relative amplitude of the global gain oscillation (0 = constant light)
    occlusion: bool = False  # a static occluder sits on the object's path around mid-video
    noise: float = 2.0  # grey levels, std of the white sensor noise

    def __post_init__(self) -> None:
        w, h = self.object_size
        checks = {
            "width": (self.width, 16, 8192), "height": (self.height, 16, 8192), "n_frames": (self.n_frames, 1, 10**6),
            "fps": (self.fps, 1e-3, 1e4), "speed": (self.speed, 0, 1e5), "max_speed": (self.max_speed, 1e-9, 1e5),
            "sigma_w": (self.sigma_w, 0, 1e6), "manoeuvre_rate": (self.manoeuvre_rate, 0, 1e3),
            "manoeuvre_accel": (self.manoeuvre_accel, 0, 1e6), "scale_change": (self.scale_change, 0, 1.0),
            "rotation": (self.rotation, 0, 45), "deformation": (self.deformation, 0, 0.5),
            "camera_motion": (self.camera_motion, 0, 1e4), "blur": (self.blur, 0, 50),
            "illumination": (self.illumination, 0, 0.9), "noise": (self.noise, 0, 100),
            "object_size[0]": (w, 4, self.width / 2), "object_size[1]": (h, 4, self.height / 2),
        }
        for name, (value, lo, hi) in checks.items():
            if not (np.isfinite(value) and lo <= value <= hi):
                raise ValueError(f"VideoScenario.{name}={value!r} is out of range: allowed [{lo}, {hi}]")
        lo, hi = self.manoeuvre_duration
        if not 0 < lo <= hi:
            raise ValueError(f"VideoScenario.manoeuvre_duration={self.manoeuvre_duration!r}; "
                             "allowed 0 < low <= high (s)")

    @property
    def tau(self) -> float:
        """s, frame interval."""
        return 1.0 / self.fps


@dataclass(frozen=True)
class VideoRanges:
    """Distribution of :class:`VideoScenario` for seeded variety ((low, high): log-uniform for sizes,
    uniform otherwise; probabilities switch camera motion / occlusion on). Object sides are capped at 40 % of
    the frame's width / height (so small test frames stay valid)."""

    width: int = 320  # px
    height: int = 240  # px
    n_frames: int = 200
    fps: float = 30.0  # frames/s
    size: tuple[float, float] = (28.0, 64.0)  # px, object w and h (each log-uniform)
    speed: tuple[float, float] = (20.0, 120.0)  # px/s
    manoeuvre_rate: tuple[float, float] = (0.2, 1.0)  # 1/s
    manoeuvre_accel: tuple[float, float] = (50.0, 250.0)  # px/s²
    scale_change: tuple[float, float] = (0.0, 0.25)
    rotation: tuple[float, float] = (0.0, 10.0)  # deg
    deformation: tuple[float, float] = (0.0, 0.1)
    camera_probability: float = 0.5
    camera_motion: tuple[float, float] = (5.0, 25.0)  # px, when the camera moves
    blur: tuple[float, float] = (0.0, 1.5)  # px
    illumination: tuple[float, float] = (0.0, 0.3)
    occlusion_probability: float = 0.3
    noise: tuple[float, float] = (1.0, 6.0)  # grey levels

    def sample(self, rng: np.random.Generator) -> VideoScenario:
        size = np.minimum(np.exp(rng.uniform(np.log(self.size[0]), np.log(self.size[1]), 2)),
                          0.4 * np.array([self.width, self.height]))
        camera = rng.uniform(*self.camera_motion) if rng.random() < self.camera_probability else 0.0
        return VideoScenario(
            width=self.width, height=self.height, n_frames=self.n_frames, fps=self.fps,
            object_size=(float(size[0]), float(size[1])), speed=float(rng.uniform(*self.speed)),
            manoeuvre_rate=float(rng.uniform(*self.manoeuvre_rate)),
            manoeuvre_accel=float(rng.uniform(*self.manoeuvre_accel)),
            scale_change=float(rng.uniform(*self.scale_change)), rotation=float(rng.uniform(*self.rotation)),
            deformation=float(rng.uniform(*self.deformation)), camera_motion=float(camera),
            blur=float(rng.uniform(*self.blur)), illumination=float(rng.uniform(*self.illumination)),
            occlusion=bool(rng.random() < self.occlusion_probability), noise=float(rng.uniform(*self.noise)),
        )


@dataclass(frozen=True, eq=False)
class SyntheticVideo:
    """A rendered-on-demand video: trajectories are precomputed, frames are drawn by :meth:`frame`."""

    scenario: VideoScenario
    seed: int
    boxes: np.ndarray  # (T, 4) xywh ground truth in image coordinates, px
    centres: np.ndarray  # (T, 2) object centre in image coordinates, px
    shapes: np.ndarray  # (T, 2, 2) linear map texture → image (rotation · scale), about the texture centre
    camera: np.ndarray  # (T, 2) camera offset, px (frame 0: 0)
    gain: np.ndarray  # (T,) global illumination gain
    background: np.ndarray  # (Hb, Wb, 3) float32 world texture; world (0, 0) is at index (margin, margin)
    occluder: np.ndarray | None  # (Hb, Wb, 4) float32 premultiplied BGR + alpha layer in front of the object
    texture: np.ndarray  # (h0, w0, 4) float32 premultiplied object BGR + alpha
    margin: int  # px of background beyond the frame on every side

    def __len__(self) -> int:
        return len(self.boxes)

    @property
    def tau(self) -> float:
        return self.scenario.tau

    def frame(self, t: int) -> np.ndarray:
        """Frame ``t`` as BGR uint8 (H, W, 3)."""
        if not 0 <= t < len(self):
            raise ValueError(f"frame index t={t} is out of range: allowed 0 <= t < {len(self)}")
        sc = self.scenario
        size = (sc.width, sc.height)
        cam = np.array([[1.0, 0.0, self.camera[t, 0] + self.margin], [0.0, 1.0, self.camera[t, 1] + self.margin]])
        flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
        img = cv2.warpAffine(self.background, cam, size, flags=flags, borderMode=cv2.BORDER_REFLECT)
        A, c = self.shapes[t], self.centres[t]
        half_tex = 0.5 * np.array(self.texture.shape[1::-1], dtype=float)
        # corner coordinates u_dst = A (u_src − half_tex) + c; pixel centres sit at u − 0.5
        obj = np.column_stack([A, A @ (0.5 - half_tex) + c - 0.5])
        layers = [cv2.warpAffine(self.texture, obj, size, flags=cv2.INTER_LINEAR, borderValue=0)]
        if self.occluder is not None:
            layers.append(cv2.warpAffine(self.occluder, cam, size, flags=flags, borderValue=0))
        for layer in layers:  # premultiplied "over" compositing
            img = img * (1.0 - layer[..., 3:]) + layer[..., :3]
        if sc.blur > 0:
            img = cv2.GaussianBlur(img, (0, 0), sc.blur)
        img = img * self.gain[t]
        if sc.noise > 0:
            white = np.random.default_rng((self.seed, 1, t)).standard_normal(img.shape[:2], np.float32)
            img += sc.noise * white[..., None]
        return np.clip(img + 0.5, 0, 255).astype(np.uint8)

    def __iter__(self) -> Iterator[np.ndarray]:
        return (self.frame(t) for t in range(len(self)))


def render(scenario: VideoScenario, seed: int) -> SyntheticVideo:
    """Draw the trajectories and textures of a video from ``seed`` (frames are rendered on demand)."""
    rng = np.random.default_rng((seed, 0))
    T, tau = scenario.n_frames, scenario.tau
    t = np.arange(T) * tau
    camera = _camera_path(scenario, rng, t)
    w0, h0 = (int(round(v)) for v in scenario.object_size)
    shapes = _shape_maps(scenario, rng, t)
    half = 0.5 * np.abs(shapes) @ np.array([w0, h0], dtype=float)  # (T, 2) half extents of the rotated object
    centre = _object_path(scenario, rng, camera, half.max(axis=0) + 2.0)
    boxes = np.column_stack([centre - half, 2.0 * half])
    margin = int(np.ceil(np.abs(camera).max())) + 4
    hue = int(rng.integers(0, 180))
    background = _background(rng, scenario.height + 2 * margin, scenario.width + 2 * margin, hue)
    texture = _object_texture(rng, h0, w0, hue)
    occluder = _occluder(scenario, rng, background.shape[:2], margin, centre + camera, half)
    phase = rng.uniform(0, 2 * np.pi)
    gain = 1.0 + scenario.illumination * (np.sin(2 * np.pi * rng.uniform(0.05, 0.25) * t + phase) - np.sin(phase))
    return SyntheticVideo(scenario=scenario, seed=seed, boxes=boxes, centres=centre, shapes=shapes, camera=camera,
                          gain=gain.astype(np.float32),
                          background=background, occluder=occluder, texture=texture, margin=margin)


def synthetic_video(seed: int, ranges: VideoRanges | None = None) -> SyntheticVideo:
    """The video of ``seed`` with its scenario drawn from ``ranges`` (default :class:`VideoRanges`)."""
    scenario = (ranges or VideoRanges()).sample(np.random.default_rng((seed, 2)))
    return render(scenario, seed)


def _camera_path(sc: VideoScenario, rng: np.random.Generator, t: np.ndarray) -> np.ndarray:
    """Pan (0.1–0.4 Hz, amplitude A) plus shake (1–3 Hz, A/4) per axis, starting at 0."""
    if sc.camera_motion == 0:
        return np.zeros((len(t), 2))
    amp = sc.camera_motion * np.array([1.0, 0.25])[:, None] * rng.uniform(0.5, 1.0, (2, 2))  # (component, axis)
    freq = np.array([rng.uniform(0.1, 0.4, 2), rng.uniform(1.0, 3.0, 2)])
    phase = rng.uniform(0, 2 * np.pi, (2, 2))
    arg = 2 * np.pi * freq[None] * t[:, None, None] + phase[None]  # (T, component, axis)
    return (amp[None] * (np.sin(arg) - np.sin(phase)[None])).sum(axis=1)


def _shape_maps(sc: VideoScenario, rng: np.random.Generator, t: np.ndarray) -> np.ndarray:
    """A_t = R(θ_t) · diag(s_t e^{d_t}, s_t e^{−d_t}) (T, 2, 2): smooth scale s, wobble θ, deformation d."""
    def wave(amp: float, lo: float, hi: float) -> np.ndarray:
        return amp * np.sin(2 * np.pi * rng.uniform(lo, hi) * t + rng.uniform(0, 2 * np.pi))

    s = np.exp(wave(sc.scale_change, 0.05, 0.3))
    theta, d = np.deg2rad(wave(sc.rotation, 0.3, 1.5)), wave(sc.deformation, 0.5, 2.0)
    cos, sin = np.cos(theta), np.sin(theta)
    R = np.stack([np.stack([cos, -sin], -1), np.stack([sin, cos], -1)], -2)
    return R * (s[:, None] * np.exp(np.stack([d, -d], -1)))[:, None, :]


def _object_path(sc: VideoScenario, rng: np.random.Generator, camera: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Image-plane centres (T, 2): world CV motion + manoeuvres + white acceleration, reflected at the
    borders so that the object (half extents ``half`` (2,)) stays inside the frame."""
    T, tau = sc.n_frames, sc.tau
    t = np.arange(T) * tau
    n_man = rng.poisson(sc.manoeuvre_rate * T * tau)
    onset = rng.uniform(0, T * tau, n_man)
    end = onset + rng.uniform(*sc.manoeuvre_duration, n_man)
    active = (t[:, None] >= onset[None]) & (t[:, None] < end[None])  # (T, n_man)
    accel = active @ rng.normal(0, sc.manoeuvre_accel, (n_man, 2)) + rng.normal(0, sc.sigma_w, (T, 2))
    lo, hi = half, np.array([sc.width, sc.height]) - half
    q = rng.uniform(lo, hi)
    angle = rng.uniform(0, 2 * np.pi)
    v = sc.speed * np.array([np.cos(angle), np.sin(angle)])
    out = np.empty((T, 2))
    p = q + camera[0]
    for n in range(T):  # loop over time (reflection at the borders)
        if n > 0:
            p = p + tau * v + 0.5 * tau**2 * accel[n]  # x_n = F x_{n-1} + B w_n (CV, backward Euler)
            v = v + tau * accel[n]
            speed = np.hypot(*v)
            if speed > sc.max_speed:
                v = v * (sc.max_speed / speed)
        q = p - camera[n]
        below, above = q < lo, q > hi
        q = np.where(below, 2 * lo - q, np.where(above, 2 * hi - q, q))
        v = np.where(below, np.abs(v), np.where(above, -np.abs(v), v))
        q = np.clip(q, lo, hi)
        p = q + camera[n]
        out[n] = q
    return out


def _noise_field(rng: np.random.Generator, h: int, w: int, cells: tuple[int, ...],
                 weights: tuple[float, ...]) -> np.ndarray:
    """Multi-octave value noise in [0, 1] (float32, (h, w)): bicubic upsampling of random grids."""
    out = np.zeros((h, w), np.float32)
    for cell, weight in zip(cells, weights, strict=False):
        grid = rng.random((h // cell + 2, w // cell + 2)).astype(np.float32)
        out += weight * cv2.resize(grid, (w, h), interpolation=cv2.INTER_CUBIC)
    out -= out.min()
    return out / max(float(out.max()), 1e-6)


def _hsv_to_bgr(h: np.ndarray, s: np.ndarray, v: np.ndarray) -> np.ndarray:
    hsv = np.stack([h, s * 255, v * 255], axis=-1)
    return cv2.cvtColor(np.clip(hsv, 0, 255).astype(np.uint8), cv2.COLOR_HSV2BGR).astype(np.float32)


def _far_hue(rng: np.random.Generator, hue: int, n: int) -> np.ndarray:
    """``n`` hues at least ``_OBJECT_HUE_GAP`` away from ``hue`` on the 180-unit circle."""
    return (hue + _OBJECT_HUE_GAP + rng.uniform(0, 180 - 2 * _OBJECT_HUE_GAP, n)) % 180


def _background(rng: np.random.Generator, h: int, w: int, hue: int) -> np.ndarray:
    """Low-saturation textured ground with coloured clutter shapes (hues far from the object's)."""
    value = 0.25 + 0.6 * _noise_field(rng, h, w, (48, 12, 3), (0.5, 0.3, 0.2))
    sat = 0.05 + 0.2 * _noise_field(rng, h, w, (64,), (1.0,))
    img = _hsv_to_bgr(np.full((h, w), _far_hue(rng, hue, 1)[0]), sat, value)
    n_shapes = int(h * w / 2500)
    colours = _hsv_to_bgr(_far_hue(rng, hue, n_shapes)[None], rng.uniform(0.1, 0.8, (1, n_shapes)),
                          rng.uniform(0.2, 0.95, (1, n_shapes)))[0]
    centres = rng.uniform((0, 0), (w, h), (n_shapes, 2)).astype(int)
    radii = rng.uniform(3, 14, (n_shapes, 2)).astype(int)
    for c, r, colour, kind in zip(centres, radii, colours, rng.integers(0, 2, n_shapes), strict=False):  # texture set-up only
        if kind:
            cv2.ellipse(img, tuple(map(int, c)), tuple(map(int, r)), 0, 0, 360, colour.tolist(), -1, cv2.LINE_AA)
        else:
            cv2.rectangle(img, tuple(map(int, c - r)), tuple(map(int, c + r)), colour.tolist(), -1)
    return img


def _object_texture(rng: np.random.Generator, h: int, w: int, hue: int) -> np.ndarray:
    """Object of one hue with a fine pattern in value *and* saturation (so it has grey-level contrast
    whatever the hue) and a few blobs (features for SIFT/ORB)."""
    value = 0.5 + 0.5 * _noise_field(rng, h, w, (6, 3), (0.6, 0.4))
    sat = 0.35 + 0.65 * _noise_field(rng, h, w, (5, 3), (0.6, 0.4))
    for _ in range(int(rng.integers(3, 7))):  # texture set-up only
        c = tuple(map(int, rng.uniform((0, 0), (w, h))))
        r = tuple(map(int, rng.uniform(2, max(3, min(w, h) / 4), 2)))
        angle, dark = float(rng.uniform(0, 180)), bool(rng.random() < 0.5)
        cv2.ellipse(value, c, r, angle, 0, 360, 0.5 if dark else 1.0, -1, cv2.LINE_AA)
        cv2.ellipse(sat, c, r, angle, 0, 360, 1.0 if dark else 0.35, -1, cv2.LINE_AA)
    bgr = _hsv_to_bgr(np.full((h, w), hue), sat, value)
    return np.concatenate([bgr, np.ones((h, w, 1), np.float32)], axis=-1)  # alpha 1: premultiplied = plain


def _occluder(sc: VideoScenario, rng: np.random.Generator, shape: tuple[int, int], margin: int, world: np.ndarray,
              extent: np.ndarray) -> np.ndarray | None:
    """A grey mottled block centred on the object's world position at a random frame n in [0.3 T, 0.7 T],
    chosen among those where the block stays clear of the object's first-frame box (the initial box must
    show the object); ``None`` if no such frame exists."""
    if not sc.occlusion:
        return None
    half = rng.uniform(0.8, 1.3) * extent  # (T, 2) occluder half sizes, one candidate per frame
    first = extent[0]
    frames = np.arange(int(0.3 * sc.n_frames), int(0.7 * sc.n_frames) + 1)
    clear = np.any(np.abs(world[frames] - world[0]) > half[frames] + first, axis=1)
    if not clear.any():
        return None
    n = int(rng.choice(frames[clear]))
    layer = np.zeros((*shape, 4), np.float32)
    x0, y0 = np.maximum(world[n] - half[n] + margin, 0).astype(int)
    x1, y1 = np.minimum(world[n] + half[n] + margin, (shape[1], shape[0])).astype(int)
    grey = 80 + 80 * _noise_field(rng, y1 - y0, x1 - x0, (8,), (1.0,))
    layer[y0:y1, x0:x1, :3] = grey[..., None]
    layer[y0:y1, x0:x1, 3] = 1.0
    return layer
