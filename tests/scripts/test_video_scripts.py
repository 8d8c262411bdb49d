"""scripts/track_video.py, video_table.py and video_camera.py on tiny inputs."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from bboxtune.agents.commands import track_video, video_camera, video_table
from bboxtune.agents.smoothing.video_tuning import fixed_tuner
from bboxtune.envs.video.synthetic import VideoScenario, render

from .cli_misuse import check_misuse, misuse

SUMMARY_KEYS = ("raw_success_auc", "filtered_success_auc", "n_frames", "n_missing")


def rows(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return list(csv.DictReader(f))


def test_track_video_synthetic(tmp_path):
    out = tmp_path / "track"
    track_video.main(["--synthetic", "--n-frames", "30", "--detector", "template", "--filter", "kf",
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
    track_video.main(["--frames", str(folder), "--detector", "regions", "--filter", "ufir",
                      "--no-video", "--out", str(out)])
    first = rows(out / "frames.csv")[0]
    np.testing.assert_allclose([float(first["raw_x"]), float(first["gt_x"])], [gt[0, 0], gt[0, 0]], atol=1e-3)
    assert json.loads((out / "summary.json").read_text())["raw_success_auc"] > 0.5


def test_track_video_with_a_trained_run(tmp_path, tiny_run):
    out = tmp_path / "tuned"
    track_video.main(["--synthetic", "--n-frames", "20", "--detector", "regions", "--tuned", str(tiny_run),
                      "--no-video", "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["filter"] == "ufir_cmn" and set(summary["params"]) == {"psi", "horizon"}


def test_video_table_tiny(tmp_path):
    out = tmp_path / "table"
    video_table.main(["--n-test", "3", "--n-train", "1", "--frames", "30", "--detectors", "regions",
                      "template", "--backends", "kf", "--grid", "3", "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text())["detectors"]
    assert set(summary) == {"regions", "template"}
    assert {"rule", "tuned"} <= set(summary["regions"]["kf"])
    table = (out / "table.md").read_text()
    assert table.count("| regions |") == 2  # the means table and the worst-video table
    results = rows(out / "results.csv")
    assert len(results) == 3 * 2 * 3  # videos × detectors × methods
    for detector in ("regions", "template"):  # the worst video is the lowest AUC in results.csv
        s = summary[detector]
        for method, reported in (("raw", s["raw_worst"]), ("rule", s["kf"]["rule"]["worst"]),
                                 ("tuned", s["kf"]["tuned"]["worst"])):
            mine = [r for r in results if r["detector"] == detector and r["method"] == method]
            low = min(mine, key=lambda r: float(r["success_auc"]))
            assert reported["video"] == low["video"], (detector, method)
            assert reported["success_auc"] == pytest.approx(float(low["success_auc"]), abs=1e-5)
            assert f"{reported['success_auc']:.3f} ({low['video']})" in table
    assert (out / "tuned" / "template-kf.json").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table"]  # no temporary folder left behind


def test_video_table_refuses_a_used_out(tmp_path, capsys):
    out = tmp_path / "table"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    with pytest.raises(SystemExit) as exc:
        video_table.main(["--n-test", "2", "--frames", "30", "--detectors", "regions",
                          "--out", str(out)])
    assert exc.value.code == 2 and "not empty" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == ["keep.txt"]


COUNT = ("0", "-1", "abc", "1_0", "2.5")  # not integers >= 1 ("1_0" is 10 to int())
TABLE_MISUSE = [
    *[misuse("--n-test", v) for v in (*COUNT, "1", "1000001")],  # the bootstrap needs >= 2 videos
    *[misuse("--n-train", v) for v in COUNT],
    *[misuse("--frames", v) for v in ("7", "0", "abc", "100001")],  # the env takes 8 … 100 000 frames
    *[misuse("--grid", v) for v in ("1", "abc", "101")],  # 101² grid points for ufir_cmn: over 10 000
    misuse("--backends", "kf_cmn", "--grid", "22"),  # 22³ > 10 000
    misuse("--seed", "-1"), misuse("--detectors", "surf"), misuse("--backends", "nope"),
    misuse("--backends", "kf", "kf"), misuse("--detectors"), misuse("--n-tes", "3", mentions="--n-tes"),
    misuse("--out", "{file}"), misuse("--out", "{under_file}"), misuse("--out", ""),
    misuse("--out", "{dir}/..", mentions="not empty"),  # the temporary folder holding the placeholders
    misuse("--cache", "{file}"), misuse("--cache", "{under_file}"), misuse("--out", "{out}", "--cache", "{out}/c"),
    misuse("--tuned", "{missing}"), misuse("--tuned", "{dir}"), misuse("--tuned", "{file}"),
    misuse("--tuned", "{bad_json}", mentions="{bad_json}:2"),
    misuse("--trust-pickle", mentions="--tuned"),
]


@pytest.mark.parametrize("case", TABLE_MISUSE, ids=str)
def test_video_table_misuse(case, misuse_paths, capsys):
    check_misuse(video_table.main, case, misuse_paths, capsys)


def test_video_table_tuned_backend_conflict(misuse_paths, capsys):
    tuned = misuse_paths.root / "tuned.json"
    tuned.write_text(json.dumps(fixed_tuner("kf", np.zeros(2)).document()))  # a grid-searched kf action
    check_misuse(video_table.main, misuse("--tuned", str(tuned), "--backends", "ufir_cmn"),
                 misuse_paths, capsys)


def test_video_camera_tiny(tmp_path):
    out = tmp_path / "camera"
    video_camera.main(["--n-videos", "2", "--frames", "30", "--smoothing", "1", "10", "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["by_smoothing"]) == {"1.0", "10.0"} and (out / "camera.png").is_file()
