"""TEMPORARY compatibility module (issue 11), to be deleted: the training data now live in
:mod:`mcbench.training_data` and the seed layouts in :mod:`mcbench.seeds`.

Kept only for the importers not yet switched: ``workflow/rules/common.smk``
(``training_seeds``, from :mod:`mcbench.seeds`) and ``tests/test_learned_denoisers.py``
(``training_example``, ``scene_fingerprint``, ``training_scene_fingerprint``, from
:mod:`mcbench.training_data`).
"""

from mcbench.seeds import training_seeds
from mcbench.training_data import scene_fingerprint, training_example, training_scene_fingerprint

__all__ = ["training_seeds", "training_example", "scene_fingerprint", "training_scene_fingerprint"]
