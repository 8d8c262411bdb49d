"""The back ends by name: :data:`NAMES`, :data:`PEER_NAMES`, :func:`filter_class`, :func:`make` (each module is
imported on first use)."""

from __future__ import annotations

from functools import cache
from importlib import import_module
from typing import Any

from bboxtune.filters.base import Filter
from bboxtune.filters.model import StateSpaceModel

NAMES: tuple[str, ...] = ("kf", "kf_cmn", "ufir", "ufir_cmn", "ofir", "oufir", "fir", "ukf")
# The box Kalman filters trackers ship (ByteTrack / DeepSORT, SORT): whole-box back ends with their own parameters
# (no sigma_w / sigma_v, boxes only), so not among the NAMES that the envs and their tests iterate over
PEER_NAMES: tuple[str, ...] = ("bytetrack_kf", "sort_kf")

# name -> (module, class); imported on first use
_REGISTRY: dict[str, tuple[str, str]] = {
    "kf": ("bboxtune.filters.kf", "KF"),
    "kf_cmn": ("bboxtune.filters.kf_cmn", "KFCMN"),
    "ufir": ("bboxtune.filters.ufir", "UFIR"),
    "ufir_cmn": ("bboxtune.filters.ufir_cmn", "UFIRCMN"),
    "ofir": ("bboxtune.filters.ofir", "OFIR"),
    "oufir": ("bboxtune.filters.oufir", "OUFIR"),
    "fir": ("bboxtune.filters.fir", "KwonFIR"),
    "ukf": ("bboxtune.filters.ukf", "UKF"),
    "bytetrack_kf": ("bboxtune.filters.bytetrack_kf", "ByteTrackKF"),
    "sort_kf": ("bboxtune.filters.sort_kf", "SortKF"),
    # SORT's filter with two noise scales per track: the search tuner's candidates (bboxtune.agents.tracking.search_tune)
    "sort_kf_scaled": ("bboxtune.filters.sort_kf", "ScaledSortKF"),
}


@cache
def filter_class(name: str) -> type[Filter]:
    """The :class:`Filter` subclass of back end ``name`` (one of :data:`NAMES` or :data:`PEER_NAMES`)."""
    if name not in _REGISTRY:
        raise ValueError(f"name={name!r} is not a filter; allowed: {', '.join(NAMES + PEER_NAMES)}")
    module, cls = _REGISTRY[name]
    return getattr(import_module(module), cls)


def make(name: str, model: StateSpaceModel, **params: Any) -> Filter:
    """Configure back end ``name`` for ``model``; ``params`` as documented by its class.

    ValueError for an unknown ``name`` or parameter, or a value out of its documented range
    (:mod:`bboxtune.filters.validation`); TypeError naming ``model`` if it is not a
    :class:`~bboxtune.filters.model.StateSpaceModel`, and naming the parameter for a value that is not a number
    (a str such as ``'1'``, a bool, None: never coerced).

    >>> from bboxtune import filters
    >>> filters.make("kf", filters.constant_velocity(0.1), sigma_w="1")
    Traceback (most recent call last):
    ...
    TypeError: sigma_w='1' (str) is not a number; allowed: a number ... with 1e-30 <= sigma_w <= 1e+30
    """
    if not isinstance(name, str):
        raise TypeError(f"name={name!r} ({type(name).__name__}); allowed: one of {', '.join(NAMES + PEER_NAMES)}")
    return filter_class(name)(model, **params)
