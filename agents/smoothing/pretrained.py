"""Pretrained tuners shipped as package data, loadable by name.

Each tuner is a folder ``agents/pretrained/<name>/`` holding the files of a ``scripts/train.py`` run that
:class:`bboxtune.agents.smoothing.tuner.Tuner` needs, and no pickle::

    model.zip           the PPO model (loaded by bboxtune.agents.training.safe_load: nothing in it is unpickled)
    vecnormalize.json   its observation statistics (bboxtune.agents.training.run_files)
    config.yml          the run's config: env id and env kwargs (source, back end), algorithm, hyperparameters;
                        optionally backend_params (bboxtune.agents.smoothing.tuner: settings outside the action)
    summary.md          the compare.py summary it reached (test split of its env)
    gate.json           optional: its learned gate (bboxtune.agents.policies.gate_file; compare.py --gate), applied
    when it is loaded

Names are the folders found there (``<source>_<backend>``, e.g. ``sim_ufir_cmn``; ``otb_tracker_<backend>`` for
tracker output); a folder is added by copying a run's ``model.zip``, ``vecnormalize.json`` and ``config.yml``
and its ``compare/summary.md`` into it. :func:`bboxtune.agents.smoothing.tuner.load_pretrained` loads one (cached per process).
"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "pretrained"  # agents/pretrained/
FILES = ("model.zip", "vecnormalize.json", "config.yml", "summary.md")
OPTIONAL = ("gate.json",)


def available() -> tuple[str, ...]:
    """Names of the pretrained tuners (the folders under :data:`ROOT`), sorted."""
    if not ROOT.is_dir():
        return ()
    return tuple(sorted(p.name for p in ROOT.iterdir() if p.is_dir() and not p.name.startswith((".", "_"))))


def folder(name: str) -> Path:
    """The folder of the pretrained tuner ``name``; ValueError listing the available ones if there is none, or
    naming the file it lacks."""
    names = available()
    if not isinstance(name, str) or name not in names:
        raise ValueError(f"pretrained tuner {name!r} is not installed; available: {', '.join(names) or 'none'}")
    path = ROOT / name
    missing = [f for f in FILES if not (path / f).is_file()]
    if missing:
        raise ValueError(f"pretrained tuner {name!r} is incomplete: {path} lacks {', '.join(missing)}")
    return path


def summary(name: str) -> str:
    """The compare.py summary (markdown) the tuner ``name`` reached."""
    return (folder(name) / "summary.md").read_text(encoding="utf-8")
