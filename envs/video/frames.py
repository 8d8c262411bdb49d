"""Frames from a video file or a folder of numbered images (the OTB layout ``<Video>/img/0001.jpg``).

Frames are yielded lazily as BGR uint8 (H, W, 3), so long videos are never held in memory.

OTB folders: the boxes of a sequence start at image ``first_frame`` (``sequences.csv``; e.g. BlurCar1 at
247, David at 300) and last ``n_frames`` images; :func:`otb_frames` looks the sequence up in an OTB data
folder (``otb_root`` or ``$OTB_ROOT``, any layout :class:`bboxtune.envs.data.otb.OTBDataset` reads) and returns the
matching images together with the ground truth, falling back to ``groundtruth_rect.txt`` inside the folder
and then to all images from 1 without ground truth. OTB boxes are 1-based (Matlab) pixel coordinates.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from bboxtune.envs.data.otb import OTBDataset, read_boxes

IMAGE_EXTENSIONS = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff")


@dataclass(frozen=True)
class ImageFolder:
    """Numbered images read one at a time."""

    paths: tuple[Path, ...]
    fps: float = 30.0  # frames/s (OTB: 30)

    def __len__(self) -> int:
        return len(self.paths)

    def __iter__(self) -> Iterator[np.ndarray]:
        for path in self.paths:
            img = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if img is None:
                raise ValueError(f"{path}: not a readable image")
            yield img


@dataclass(frozen=True)
class VideoFile:
    """A video file decoded by OpenCV; ``n_frames`` is the container's frame count (0 if unknown)."""

    path: Path
    n_frames: int
    fps: float  # frames/s from the container (30 if it has none)

    def __len__(self) -> int:
        return self.n_frames

    def __iter__(self) -> Iterator[np.ndarray]:
        cap = cv2.VideoCapture(str(self.path))
        try:
            while True:
                ok, frame = cap.read()
                if not ok:
                    return
                yield frame
        finally:
            cap.release()


def video_file(path: str | os.PathLike) -> VideoFile:
    """Open a video file (ValueError if OpenCV cannot decode it)."""
    path = Path(path)
    if not path.is_file():  # checked first: OpenCV blocks forever on a named pipe
        raise ValueError(f"{path}: not a readable video file")
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise ValueError(f"{path}: not a readable video file")
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        fps = float(cap.get(cv2.CAP_PROP_FPS)) or 30.0
    finally:
        cap.release()
    return VideoFile(path=path, n_frames=max(n, 0), fps=fps if np.isfinite(fps) and fps > 0 else 30.0)


def image_folder(folder: str | os.PathLike, *, first_frame: int = 1, n_frames: int | None = None,
                 fps: float = 30.0) -> ImageFolder:
    """Images numbered ``first_frame`` … ``first_frame + n_frames − 1`` (all from ``first_frame`` if
    ``n_frames`` is None) in ``folder`` or in its ``img/`` sub-folder; file stems are the numbers
    (``0001.jpg``). A number missing in that range, or two files of one number (``1.jpg`` and ``0001.png``),
    raises ValueError naming them."""
    root = Path(folder)
    images = root / "img" if (root / "img").is_dir() else root
    if not images.is_dir():
        raise ValueError(f"{folder}: not a folder of images")
    numbered: dict[int, Path] = {}
    for path in sorted(images.iterdir()):
        if path.suffix.lower() in IMAGE_EXTENSIONS and re.fullmatch(r"[0-9]+", path.stem) and path.is_file():
            other = numbered.setdefault(int(path.stem), path)
            if other is not path:
                raise ValueError(f"{images}: {other.name} and {path.name} are both image {int(path.stem)}; keep one")
    if not numbered:
        raise ValueError(f"{images}: no numbered images ({', '.join(IMAGE_EXTENSIONS)})")
    if first_frame < 1:
        raise ValueError(f"first_frame={first_frame}; allowed: >= 1")
    last = max(numbered) if n_frames is None else first_frame + n_frames - 1
    wanted = range(first_frame, last + 1)
    missing = [n for n in wanted if n not in numbered]
    if missing or not wanted:
        raise ValueError(f"{images}: images {first_frame}..{last} wanted; missing {missing[:5] or 'all'}")
    return ImageFolder(paths=tuple(numbered[n] for n in wanted), fps=fps)


def otb_frames(folder: str | os.PathLike, *, sequence: str | None = None,
               otb_root: str | os.PathLike | None = None) -> tuple[ImageFolder, np.ndarray | None, str]:
    """Images and ground truth of an OTB sequence: (frames, gt (T, 4) xywh 1-based OTB or None, name).

    ``sequence`` defaults to the folder's name (the parent's if ``folder`` is an ``img`` folder). The first
    frame and length come from the OTB data folder when it knows the sequence (``sequences.csv``), else
    from ``groundtruth_rect.txt`` in ``folder`` (first frame 1), else all images from 1, without truth."""
    path = Path(folder)
    name = sequence or (path.parent.name if path.name == "img" else path.name)
    if otb_root is not None or os.environ.get("OTB_ROOT"):
        dataset = OTBDataset(otb_root)
        if name in dataset.names:
            seq = dataset.sequence(name)
            return image_folder(folder, first_frame=seq.first_frame, n_frames=seq.n_frames), seq.gt, name
        if sequence is not None:
            raise ValueError(f"sequence={sequence!r} is not in the OTB data under {dataset.root}")
    gt_file = (path.parent if path.name == "img" else path) / "groundtruth_rect.txt"
    if gt_file.is_file():
        gt = read_boxes(gt_file)
        return image_folder(folder, n_frames=len(gt)), gt, name
    return image_folder(folder), None, name
