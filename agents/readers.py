"""JSON and YAML files read with errors that name them: ``file:line:column: why`` (ValueError), bounded in size
(:mod:`bboxtune.envs.data.textfile`), strict JSON (no ``NaN`` / ``Infinity``), YAML through ``yaml.safe_load``; and
checked numbers out of a parsed JSON object. Used by the command-line checks (:mod:`bboxtune.agents.cli`) and by
every reader of run, gate and hyperparameter files."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import yaml

from bboxtune.envs.data import textfile


def _read_text(path: Path) -> str:
    """The UTF-8 text of the regular file ``path`` (bounded, :mod:`bboxtune.envs.data.textfile`); ValueError naming it."""
    return textfile.read_text(path)


def _no_constant(name: str) -> NoReturn:
    raise ValueError(f"non-standard JSON constant {name}")


def read_json(path: Path) -> Any:
    """Parse a JSON file (strict: ``NaN``/``Infinity`` are refused); ValueError ``file:line:column: why``."""
    text = _read_text(Path(path))
    try:
        return json.loads(text, parse_constant=_no_constant)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}:{exc.lineno}:{exc.colno}: invalid JSON: {exc.msg}") from None
    except ValueError as exc:  # a refused constant
        raise ValueError(f"{path}: invalid JSON: {exc}") from None
    except RecursionError:
        raise ValueError(f"{path}: invalid JSON: nested too deeply") from None


def json_number(doc: Any, key: str, path: str | os.PathLike[str], low: float = -math.inf,
                error: type[ValueError] = ValueError) -> float:
    """``doc[key]`` of a parsed JSON object as a finite number >= ``low`` (not a bool); ``error`` naming ``path``."""
    value = doc.get(key) if isinstance(doc, dict) else None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < low:
        raise error(f"{path}: {key}={value!r}; expected a finite number >= {low:g}")
    return float(value)


def json_vector(doc: Any, key: str, size: int, path: str | os.PathLike[str], low: float = -math.inf, what: str = "",
                error: type[ValueError] = ValueError) -> np.ndarray:
    """``doc[key]`` of a parsed JSON object as ``size`` finite numbers >= ``low`` (float64); ``error`` naming ``path``
    (and ``what`` the size is)."""
    values = doc.get(key) if isinstance(doc, dict) else None
    if not isinstance(values, list) or len(values) != size or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= low for v in values):
        raise error(f"{path}: {key} must be a list of {size} finite numbers >= {low:g}{f' ({what})' if what else ''}")
    return np.array(values, dtype=np.float64)


def read_yaml(path: Path) -> Any:
    """Parse a YAML file with ``yaml.safe_load``; ValueError ``file:line:column: why``."""
    text = _read_text(Path(path))
    try:
        return yaml.safe_load(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark else str(path)
        raise ValueError(f"{where}: invalid YAML: {exc.problem or exc.context}") from None
    except yaml.YAMLError as exc:
        raise ValueError(f"{path}: invalid YAML: {' '.join(str(exc).split())}") from None
    except ValueError as exc:  # a value the constructor refuses, e.g. an integer of over 4300 digits
        raise ValueError(f"{path}: invalid YAML: {exc}") from None
    except RecursionError:
        raise ValueError(f"{path}: invalid YAML: nested too deeply") from None
