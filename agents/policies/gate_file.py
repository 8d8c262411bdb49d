"""A fitted gate (:mod:`bboxtune.agents.evaluation.gate`) as plain numbers: the linear gain predictor and its margin,
kept in a JSON file.

``compare.py --gate`` writes one per gated model (``gates/<name>.json`` in its output folder). ``smooth.py --gate FILE``
and ``bboxtune.agents.smoothing.tuner.Tuner`` read one, and a tuner folder holding a ``gate.json`` beside
``model.zip`` is gated when loaded.
The gate opens (the tuner's parameters are used) where ``((obs − mean) / scale) · coef + intercept > margin``; elsewhere
the track is left as measured. This module needs numpy only, so ``import agents`` stays light.

The file: ``{"about": str, "margin": number | "inf" | "-inf", "mean": [F numbers], "scale": [F numbers > 0],
"coef": [F numbers], "intercept": number}``; F is the tuner's number of observation features (strict JSON:
±infinity only as the margin's strings).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bboxtune.agents.readers import json_number, json_vector, read_json
from bboxtune.envs.data.atomic_files import write_text_atomic

GATE_FILE = "gate.json"  # the gate of a tuner folder, read when the tuner is loaded
VECTORS = ("mean", "scale", "coef")


@dataclass(frozen=True, eq=False)
class LinearGain:
    """Predicted gain of the tuner's action over the raw measurements: a ridge regression on standardised features."""

    mean: np.ndarray  # (F,) the features' means over the training episodes
    scale: np.ndarray  # (F,) their standard deviations (1 where a feature was constant)
    coef: np.ndarray  # (F,) coefficients on the standardised features
    intercept: float  # reward units

    def predict(self, obs: np.ndarray) -> np.ndarray:
        """Predicted gains (n,) of observations (n, F)."""
        return ((np.asarray(obs, dtype=np.float64) - self.mean) / self.scale) @ self.coef + self.intercept


@dataclass(frozen=True, eq=False)
class Gate:
    """A gain predictor and the margin its prediction must exceed."""

    gain: LinearGain
    margin: float  # reward units; inf: every track left alone, -inf: never

    def opens(self, obs: np.ndarray) -> np.ndarray:
        """Where the tuner's parameters are used, (n,) bool, for observations (n, F)."""
        return self.gain.predict(obs) > self.margin


def write_gate(path: Path | str, gate: Gate, about: str) -> None:
    """``gate`` as JSON at ``path`` (atomic), with a line ``about`` what it was fitted on."""
    margin = gate.margin if math.isfinite(gate.margin) else str(gate.margin)
    data = {"about": about, "margin": margin, **{k: getattr(gate.gain, k).tolist() for k in VECTORS},
            "intercept": float(gate.gain.intercept)}
    write_text_atomic(path, json.dumps(data, indent=1) + "\n")


def read_gate(path: str | os.PathLike[str], n_features: int) -> Gate:
    """The gate in the JSON file ``path`` (read as :func:`bboxtune.agents.readers.read_json` reads: bounded, strict)
    for a tuner of
    ``n_features`` observation features; ValueError naming the file and the field that is missing or malformed."""
    doc = read_json(Path(path))
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: a gate file holds a JSON object, not {type(doc).__name__}")
    vectors = {k: json_vector(doc, k, n_features, path, what="the tuner's features") for k in VECTORS}
    if not (vectors["scale"] > 0).all():
        raise ValueError(f"{path}: scale must be > 0 everywhere")
    margin = doc.get("margin")
    margin = float(margin) if margin in ("inf", "-inf") else json_number(doc, "margin", path)
    return Gate(LinearGain(intercept=json_number(doc, "intercept", path), **vectors), margin)
