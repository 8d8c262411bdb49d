"""Reading frames: numbered image folders (OTB first frames), video files, OTB ground truth lookup."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from bboxtune.envs.video.frames import image_folder, otb_frames, video_file


def write_images(folder, numbers, size=(24, 16)):
    folder.mkdir(parents=True, exist_ok=True)
    for n in numbers:
        img = np.full((size[1], size[0], 3), n, np.uint8)  # the pixel value encodes the image number
        cv2.imwrite(str(folder / f"{n:04d}.png"), img)


def test_image_folder_honours_first_frame_and_length(tmp_path):
    write_images(tmp_path / "Seq" / "img", range(1, 11))
    frames = image_folder(tmp_path / "Seq", first_frame=3, n_frames=4)
    values = [int(f[0, 0, 0]) for f in frames]
    assert len(frames) == 4 and values == [3, 4, 5, 6]
    assert [int(f[0, 0, 0]) for f in image_folder(tmp_path / "Seq" / "img", first_frame=8)] == [8, 9, 10]


def test_image_folder_missing_image_raises(tmp_path):
    write_images(tmp_path, [1, 2, 4])
    with pytest.raises(ValueError, match="missing \\[3\\]"):
        image_folder(tmp_path, n_frames=4)
    with pytest.raises(ValueError, match="not a folder"):
        image_folder(tmp_path / "nope")


def test_image_folder_two_files_of_one_number_raise(tmp_path):
    write_images(tmp_path, [1, 2])
    cv2.imwrite(str(tmp_path / "1.jpg"), np.zeros((16, 24, 3), np.uint8))  # image 1 again, another name
    with pytest.raises(ValueError, match="0001.png and 1.jpg are both image 1"):
        image_folder(tmp_path)


def test_otb_frames_use_sequences_csv_first_frame_and_ground_truth(tmp_path):
    root = tmp_path / "otb"
    (root / "groundtruth").mkdir(parents=True)
    (root / "groundtruth" / "Toy.txt").write_text("5,6,7,8\n6,6,7,8\n7,6,7,8\n")
    (root / "sequences.csv").write_text("sequence,video_dir,image_folder,n_frames,first_frame,last_frame,img_name_digits,"
                                        "img_ext\nToy,Toy,Toy,3,4,6,4,png\n")
    write_images(tmp_path / "videos" / "Toy" / "img", range(1, 9))
    frames, gt, name = otb_frames(tmp_path / "videos" / "Toy", otb_root=root)
    assert name == "Toy" and [int(f[0, 0, 0]) for f in frames] == [4, 5, 6]
    np.testing.assert_array_equal(gt[:, 0], [5, 6, 7])


def test_otb_frames_fall_back_to_groundtruth_rect(tmp_path, monkeypatch):
    monkeypatch.delenv("OTB_ROOT", raising=False)
    write_images(tmp_path / "Toy" / "img", range(1, 6))
    (tmp_path / "Toy" / "groundtruth_rect.txt").write_text("1\t2\t3\t4\n2\t2\t3\t4\n")
    frames, gt, _ = otb_frames(tmp_path / "Toy" / "img")
    assert len(frames) == 2 and gt.shape == (2, 4)
    (tmp_path / "Toy" / "groundtruth_rect.txt").unlink()
    frames, gt, _ = otb_frames(tmp_path / "Toy")
    assert len(frames) == 5 and gt is None


def test_video_file_round_trip(tmp_path):
    path = tmp_path / "clip.mp4"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 25.0, (32, 24))
    if not writer.isOpened():
        pytest.skip(reason="this OpenCV build has no mp4v VideoWriter, so there is no file to read back")
    for n in range(6):
        writer.write(np.full((24, 32, 3), 40 * n, np.uint8))
    writer.release()
    video = video_file(path)
    frames = list(video)
    assert video.fps == pytest.approx(25.0) and len(frames) == 6 and frames[0].shape == (24, 32, 3)
    assert abs(int(frames[3].mean()) - 120) < 8
    with pytest.raises(ValueError, match="not a readable video"):
        video_file(tmp_path / "missing.mp4")
