"""bboxtune tuners: stable-baselines3 agents and the non-learned baselines, in five parts.

* :mod:`bboxtune.agents.policies` — the rule, oracles, global search, the amortised regressor, adaptive KF, IMM.
* :mod:`bboxtune.agents.training` — algorithms, YAML hyperparameters (``agents/hyperparams/<algo>.yml``, RL Zoo
  layout), run directories, callbacks, checkpoints, the batched ``VecEnv``, sweeps, run files read without unpickling.
* :mod:`bboxtune.agents.evaluation` — every method scored on the same episodes, statistics, reports and plots of
  ``scripts/compare.py``, the gate and per-window regressors fitted on evaluated episodes, MOT15 evaluation.
* :mod:`bboxtune.agents.smoothing` — :func:`tune` / :func:`smooth`: a trained tuner's parameters for a track of
  boxes, and the track smoothed with them (:class:`bboxtune.agents.smoothing.tuner.Tuner`); the pretrained tuners
  by name (:mod:`bboxtune.agents.smoothing.pretrained`).
* :mod:`bboxtune.agents.tracking` — a SORT-style multi-object tracker over a pluggable box filter, optionally re-tuned
  per track from its own past (``scripts/track_mot.py``).

Below them: :mod:`bboxtune.agents.splits` (train / val / test noise seeds), :mod:`bboxtune.agents.episodes` (pinned
episodes), :mod:`bboxtune.agents.readers` (JSON / YAML files read with errors that name the file) and
:mod:`bboxtune.agents.cli` (the scripts' argument checks: one-line errors, exit status 2). Above them:
:mod:`bboxtune.agents.commands` (the scripts' command lines: ``scripts/<name>.py`` runs
``bboxtune.agents.commands.<name>.main``) and :mod:`bboxtune.agents.reproduce` (the papers' experiments of
``scripts/reproduce.py``).
"""

from bboxtune.agents.smoothing.tuner import smooth, tune

__all__ = ["smooth", "tune"]
