"""bboxtune tuners: stable-baselines3 agents and non-learned baselines.

* :mod:`agents.algos` — ``ALGOS`` (ppo, sac, td3, a2c); :mod:`agents.hyperparams` — YAML hyperparameters
  (``agents/hyperparams/<algo>.yml``, RL Zoo layout).
* :mod:`agents.baselines` — the policy interface and the rule / oracle / global / amortised baselines;
  :mod:`agents.adaptive` — the Sage–Husa adaptive KF.
* :mod:`agents.splits` — train / val / test noise-seed splits; :mod:`agents.episodes` — pinned episodes.
* :mod:`agents.runs`, :mod:`agents.callbacks`, :mod:`agents.checkpoints` — run directories and checkpoints of
  ``scripts/train.py``; :mod:`agents.safe_load`, :mod:`agents.run_files` — their files read without unpickling;
  :mod:`agents.evaluate`, :mod:`agents.stats`, :mod:`agents.report`, :mod:`agents.plots` — ``scripts/compare.py``.
* :mod:`agents.cli` — the scripts' argument checks (one-line errors, exit status 2); :mod:`agents.commands` —
  the scripts' command lines (``scripts/<name>.py`` runs ``agents.commands.<name>.main``);
  :mod:`agents.reproduce` — the papers' experiments of ``scripts/reproduce.py``; :mod:`agents.video_tables` —
  output files and folders of the video commands.
* :func:`tune` / :func:`smooth` (from :mod:`agents.tune`) — a trained tuner's parameters for a track of boxes,
  and the track smoothed with them; :mod:`agents.pretrained` — the tuners shipped with the package, by name.
  (``agents.tune`` is the function; the module is ``sys.modules["agents.tune"]`` / ``from agents.tune import …``.)
"""

from agents.tune import smooth, tune

__all__ = ["smooth", "tune"]
