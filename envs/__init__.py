"""bboxtune environments, episode sources (simulator, OTB-100 replay, tracker output, MOT15 detections), data
readers and OTB-standard metrics.

The env ids (:data:`ENV_IDS`) are registered by the package root, :mod:`bboxtune`, which every import of this
package imports first; :func:`make_vec` is ``gym.make_vec`` on them.
"""

from bboxtune import ENV_IDS, RETUNE_ID, TUNE_ID
from bboxtune.envs.vector import make_vec

__all__ = ["ENV_IDS", "RETUNE_ID", "TUNE_ID", "make_vec"]
