"""Training data of the learned denoisers: procedural scenes rendered into noisy crops + targets.

Learned denoisers (KPCN, an OIDN-style autoencoder, ...) are trained on crops of random
scenes rendered with Mitsuba, the way Firmino et al. 2022 (Sec. 5.2) complemented their pbrt
crops with "randomly generated scenes rendered in mitsuba". Everything here is seeded: the same
``seed`` gives the same scene dict (:func:`random_scene`), the same renders and the same crops
(:func:`training_example`).

Modules
-------
* :mod:`~mcbench.training_data.generator` -- :func:`random_scene`, the seeded scene generator
  (settings, objects, lights, camera), with :mod:`~mcbench.training_data.materials` (random
  BSDFs, NumPy textures) and :mod:`~mcbench.training_data.fibres` (hair/fur clumps of the fibre
  family, seeds from :data:`mcbench.render.seeds.FIBRE_SEED_BASE`);
* :mod:`~mcbench.training_data.fingerprints` -- :func:`scene_fingerprint`, to test that no
  training scene is a test scene;
* :mod:`~mcbench.training_data.examples` -- :func:`training_example`: renders (through the
  public scene-dict API of :mod:`mcbench.render.renderer`) and disjoint crops (:func:`crop_boxes`).

Render seeds (base seed 7, disjoint from every test render seed) and the scene seed families
(:func:`mcbench.render.seeds.training_seeds`) are laid out in :mod:`mcbench.render.seeds`. The generator uses only the core
building blocks :mod:`mcbench.render.geometry` and :mod:`mcbench.render.curves`, never ``scenes/``.
``snakemake --cores 2 training_data`` renders the crops of the config's ``training:`` section
(defaults in ``workflow/schemas/config.schema.yaml``).
"""

from __future__ import annotations

from mcbench.training_data.examples import crop_boxes, render_target, training_example
from mcbench.training_data.fingerprints import scene_fingerprint, training_scene_fingerprint
from mcbench.training_data.generator import random_scene

__all__ = ["random_scene", "scene_fingerprint", "training_scene_fingerprint", "crop_boxes",
           "render_target", "training_example"]
