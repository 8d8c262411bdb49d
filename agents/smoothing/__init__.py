"""Smoothing a track with a tuner: :class:`.tuner.Tuner` (a trained tuner's parameters for a track, and the track
smoothed with them; :func:`bboxtune.agents.tune` / :func:`bboxtune.agents.smooth`), the pretrained tuners
(:mod:`.pretrained`), the stock box filters as tuners (:mod:`.stock_filter`), MOT-format files (:mod:`.mot_smooth`)
and the filter parameters of video episodes (:mod:`.video_tuning`)."""
