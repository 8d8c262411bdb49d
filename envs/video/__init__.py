"""Video front end: frames → detections → filter → scored boxes.

* :mod:`envs.video.synthetic` — seeded synthetic videos with exact ground-truth boxes;
* :mod:`envs.video.frames` — frames from a video file or an OTB image folder;
* :mod:`envs.video.detectors` / :mod:`envs.video.matching` — OpenCV detectors (background subtraction,
  MOG2, region labelling; template matching, SIFT, ORB) returning one xywh box per frame, NaN when
  nothing is found;
* :mod:`envs.video.camera` — global camera-motion estimate and camera-velocity-input compensation;
* :mod:`envs.video.source` — :class:`~envs.video.source.VideoSource`, episodes for the environments;
* :mod:`envs.video.tuning` — rule / grid-searched / trained filter parameters for video episodes.
"""
