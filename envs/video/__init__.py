"""Video front end: frames → detections (one box per frame). No Gymnasium and nothing from the layers above
(:class:`~bboxtune.envs.episodes.video_source.VideoSource` turns detected videos into episodes;
:mod:`bboxtune.agents.smoothing.video_tuning`
chooses a filter's parameters for them).

* :mod:`bboxtune.envs.video.synthetic` — seeded synthetic videos with exact ground-truth boxes;
* :mod:`bboxtune.envs.video.frames` — frames from a video file or an OTB image folder;
* :mod:`bboxtune.envs.video.detector` — the :class:`~bboxtune.envs.video.detector.Detector` interface and shared image helpers;
  :mod:`bboxtune.envs.video.matching` — template matching, SIFT, ORB; :mod:`bboxtune.envs.video.detectors` — background
  subtraction, MOG2, region labelling, and the registry (``DETECTORS``, ``make_detector``, ``detect_video``),
  which imports every detector (never the other way round);
* :mod:`bboxtune.envs.video.camera` — global camera-motion estimate and camera-velocity-input compensation.
"""
