"""scripts/track_mot.py: MOT result files from a det file (the frame rate from --fps, seqinfo.ini or sequences.csv),
equal to the tracker run in-process; misuse exits 2 with one line and writes nothing; bench_track.py runs."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from bboxtune.agents.commands import bench_track, track_mot
from bboxtune.agents.tracking.search_tune import SearchSettings
from bboxtune.agents.tracking.sort_tracker import TrackerConfig, make_tracker
from bboxtune.envs.data.mot_io import read_detections, read_results

from .cli_misuse import check_misuse, misuse

MOT_ROOT = os.environ.get("MOT_ROOT")
needs_mot = pytest.mark.skipif(not MOT_ROOT, reason="MOT_ROOT is not set (CI sets it)")
DET_LINES = "".join(f"{t},-1,{100 + 4 * t},{50 + t},30,60,{0.9 if t % 5 else 0.2},-1,-1,-1\n"
                    f"{t},-1,{400 - 3 * t},80,35,70,0.8,-1,-1,-1\n" for t in range(1, 41))


def _det(folder: Path, fps: int | None = 25) -> Path:
    """A sequence folder ``folder/det/det.txt`` (two walkers, 40 frames) with a seqinfo.ini unless fps is None."""
    (folder / "det").mkdir(parents=True)
    (folder / "det" / "det.txt").write_text(DET_LINES)
    if fps is not None:
        (folder / "seqinfo.ini").write_text(f"[Sequence]\nname={folder.name}\nframeRate={fps}\n")
    return folder / "det" / "det.txt"


@pytest.mark.parametrize("args", [["--filter", "sort_kf"], ["--filter", "bytetrack_kf", "--two-stage"],
                                  ["--filter", "kf", "--params", "sigma_w=300", "sigma_v=3", "--max-age", "3"]])
def test_the_result_file_is_the_trackers_output(tmp_path: Path, args: list[str], capsys) -> None:
    det = _det(tmp_path / "Walk")
    out = tmp_path / "runs" / "sort" / "Walk.txt"  # the missing folders are created
    assert track_mot.main(["--det", str(det), "--out", str(out), *args]) == 0
    assert "40 frames" in capsys.readouterr().out
    rows = read_results(out)
    parsed = track_mot.build_parser().parse_args(["--det", str(det), "--out", "x", *args])
    config = TrackerConfig(max_age=parsed.max_age, two_stage=parsed.two_stage)
    params = {"sigma_w": 300, "sigma_v": 3} if parsed.filter == "kf" else None
    detections = read_detections(det)
    want = [(r.frame, i, b) for r in make_tracker(parsed.filter, 1 / 25, params=params, config=config).run(
        detections.frame, detections.box, detections.score) for i, b in zip(r.ids, r.boxes, strict=True)]
    assert len(rows.frame) == len(want) > 50 and set(rows.id.tolist()) == {1, 2}
    assert rows.frame.tolist() == [f for f, _, _ in want] and rows.id.tolist() == [i for _, i, _ in want]
    np.testing.assert_allclose(rows.box, np.array([b for *_, b in want]), atol=5e-4)  # written with 3 decimals


@needs_mot
def test_the_frame_rate_comes_from_the_datas_sequences_csv(tmp_path: Path) -> None:
    out = tmp_path / "KITTI-13.txt"
    det = Path(MOT_ROOT or "") / "KITTI-13" / "det" / "det.txt"
    assert track_mot.main(["--det", str(det), "--out", str(out), "--filter", "tuned", "--retune-window", "20"]) == 0
    assert len(read_results(out).frame) > 100
    assert track_mot.frame_rate(det, None, None) == 10.0  # KITTI-13: 10 fps in sequences.csv


def test_misuse_of_track_mot(tmp_path: Path, misuse_paths, capsys, monkeypatch) -> None:
    monkeypatch.delenv("MOT_ROOT", raising=False)
    det, bare = str(_det(tmp_path / "Walk")), str(_det(tmp_path / "NoRate", fps=None))
    taken = tmp_path / "taken.txt"
    taken.write_text("")
    for case in [misuse("--det", "{missing}", "--out", "{out}", mentions="--det"),
                 misuse("--det", det, "--out", str(taken), mentions="--out"),
                 misuse("--det", det, "--out", "{under_file}", mentions="--out"),
                 misuse("--det", det, "--out", "{out}", "--filter", "nope"),
                 misuse("--det", det, "--out", "{out}", "--filter", "tuned", "--params", "sigma_w=3", mentions="--params"),
                 misuse("--det", det, "--out", "{out}", "--pretrained", "mot15_det", mentions="--pretrained"),
                 misuse("--det", det, "--out", "{out}", "--search-cap", "0.5", mentions="--search-cap"),
                 misuse("--det", det, "--out", "{out}", "--filter", "search", "--search-cap", "0", mentions="--search-cap"),
                 misuse("--det", det, "--out", "{out}", "--filter", "search", "--search-width", "0.5",
                        mentions="--search-width"),
                 misuse("--det", det, "--out", "{out}", "--filter", "search", "--params", "velocity_noise_scale=2",
                        mentions="--params"),
                 misuse("--det", det, "--out", "{out}", "--filter", "sort_kf", "--retune-window", "5",
                        mentions="--retune-window"),
                 misuse("--det", det, "--out", "{out}", "--filter", "tuned", "--pretrained", "nope", mentions="nope"),
                 misuse("--det", det, "--out", "{out}", "--filter", "kf", "--params", "bogus=1", mentions="bogus"),
                 misuse("--det", det, "--out", "{out}", "--filter", "kf", "--params", "sigma_w=abc", mentions="sigma_w"),
                 misuse("--det", det, "--out", "{out}", "--filter", "sort_kf", "--params", "sigma_w=1", mentions="sigma_w"),
                 misuse("--det", det, "--out", "{out}", "--fps", "0"), misuse("--det", det, "--out", "{out}", "--fps", "nan"),
                 misuse("--det", det, "--out", "{out}", "--iou-threshold", "0"),
                 misuse("--det", det, "--out", "{out}", "--max-age", "-1"),
                 misuse("--det", det, "--out", "{out}", "--two-stage", "--low-score", "0.9", mentions="low_score"),
                 misuse("--det", bare, "--out", "{out}", mentions="--fps"),
                 misuse("--det", "{file}", "--out", "{out}", mentions="{file}:1")]:
        check_misuse(track_mot.main, case, misuse_paths, capsys, monkeypatch)


def test_the_search_filter_writes_the_trackers_output(tmp_path: Path) -> None:
    det = _det(tmp_path / "Walk")
    out = tmp_path / "Walk.txt"
    assert track_mot.main(["--det", str(det), "--out", str(out), "--filter", "search", "--retune-window", "5",
                           "--search-cap", "0.5", "--search-min-scored", "3"]) == 0
    detections = read_detections(det)
    tracker = make_tracker("search", 1 / 25, search=SearchSettings(window=5, cap=0.5, min_scored=3))
    want = [(r.frame, i, b) for r in tracker.run(detections.frame, detections.box, detections.score)
            for i, b in zip(r.ids, r.boxes, strict=True)]
    rows = read_results(out)
    assert rows.id.tolist() == [i for _, i, _ in want] and len(want) > 50
    np.testing.assert_allclose(rows.box, np.array([b for *_, b in want]), atol=5e-4)


@needs_mot
def test_bench_track_prints_a_rate_per_filter(capsys) -> None:
    assert bench_track.main(["--repeat", "1", "--filters", "sort_kf", "bytetrack_kf"]) == 0
    out = capsys.readouterr().out
    assert "1.00x sort_kf" in out and "bytetrack_kf" in out and "6 sequences" in out
