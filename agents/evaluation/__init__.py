"""Evaluation: every method scored on the same held-out episodes (:mod:`.evaluate`, :mod:`.retune_eval`),
statistics (:mod:`.stats`, :mod:`.seeds_report`), records, reports and plots of ``scripts/compare.py``
(:mod:`.records`, :mod:`.report`, :mod:`.report_otb`, :mod:`.report_retune`, :mod:`.plots`); the tuners fitted on
evaluated episodes (the gate, :mod:`.gate`; the per-window regressors of re-tuning, :mod:`.window_regressor`,
:mod:`.regime_informed`); MOT15 evaluation and the noise fit (:mod:`.mot_eval`, :mod:`.mot_fit`); the video
commands' output files (:mod:`.video_tables`)."""
