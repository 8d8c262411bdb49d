"""scripts/track_video.py, video_table.py and video_camera.py on tiny inputs."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import cv2
import numpy as np

from envs.video.synthetic import VideoScenario, render

from .tiny_run import load_script, tiny_run, train  # noqa: F401  (fixtures)

SUMMARY_KEYS = ("raw_success_auc", "filtered_success_auc", "n_frames", "n_missing")


def rows(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return list(csv.DictReader(f))


def test_track_video_synthetic(tmp_path):
    out = tmp_path / "track"
    load_script("track_video").main(["--synthetic", "--n-frames", "30", "--detector", "template", "--filter", "kf",
                                     "--seed", "4", "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text())
    assert all(k in summary for k in SUMMARY_KEYS) and summary["n_frames"] == 30
    assert 0 <= summary["raw_success_auc"] <= 1 and 0 <= summary["filtered_success_auc"] <= 1
    table = rows(out / "frames.csv")
    assert len(table) == 30 and {"raw_x", "filt_x", "gt_x", "iou_raw", "iou_filt"} <= set(table[0])
    assert (out / "video.mp4").is_file() or (out / "strip.png").is_file()
    assert not list(out.glob(".*tmp*"))  # atomic writes leave no temporary files


def test_track_video_otb_folder_keeps_one_based_boxes(tmp_path, monkeypatch):
    monkeypatch.delenv("OTB_ROOT", raising=False)
    video = render(VideoScenario(width=128, height=96, n_frames=12, object_size=(30.0, 26.0), noise=1.0), seed=1)
    folder = tmp_path / "Toy"
    (folder / "img").mkdir(parents=True)
    for n in range(12):
        cv2.imwrite(str(folder / "img" / f"{n + 1:04d}.jpg"), video.frame(n))
    gt = video.boxes + [1.0, 1.0, 0.0, 0.0]  # OTB boxes are 1-based
    (folder / "groundtruth_rect.txt").write_text("\n".join(",".join(f"{v:.3f}" for v in b) for b in gt))
    out = tmp_path / "out"
    load_script("track_video").main(["--frames", str(folder), "--detector", "regions", "--filter", "ufir",
                                     "--no-video", "--out", str(out)])
    first = rows(out / "frames.csv")[0]
    np.testing.assert_allclose([float(first["raw_x"]), float(first["gt_x"])], [gt[0, 0], gt[0, 0]], atol=1e-3)
    assert json.loads((out / "summary.json").read_text())["raw_success_auc"] > 0.5


def test_track_video_with_a_trained_run(tmp_path, tiny_run):
    out = tmp_path / "tuned"
    load_script("track_video").main(["--synthetic", "--n-frames", "20", "--detector", "regions", "--tuned", str(tiny_run),
                                     "--no-video", "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["filter"] == "ufir_cmn" and set(summary["params"]) == {"psi", "horizon"}


def test_video_table_tiny(tmp_path):
    out = tmp_path / "table"
    load_script("video_table").main(["--n-test", "2", "--n-train", "1", "--frames", "30", "--detectors", "regions",
                                     "template", "--backends", "kf", "--grid", "3", "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text())["detectors"]
    assert set(summary) == {"regions", "template"}
    assert {"rule", "tuned"} <= set(summary["regions"]["kf"])
    assert "| regions |" in (out / "table.md").read_text()
    assert len(rows(out / "results.csv")) == 2 * 2 * 3  # videos × detectors × methods
    assert (out / "tuned" / "template-kf.json").is_file()


def test_video_camera_tiny(tmp_path):
    out = tmp_path / "camera"
    load_script("video_camera").main(["--n-videos", "2", "--frames", "30", "--smoothing", "1", "10", "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["by_smoothing"]) == {"1.0", "10.0"} and (out / "camera.png").is_file()
