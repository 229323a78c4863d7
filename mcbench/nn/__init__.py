"""The training pipeline shared by every learned method (PyTorch, CPU build).

* :mod:`mcbench.nn.features` -- input transforms the papers use (log(1+x) radiance, albedo
  demodulation, delta-method noise level, normalised depth, feature gradients);
* :mod:`mcbench.nn.kernels` -- applying per-pixel kernels (KPCN) and weight-shared kernels
  (Fan et al. 2021);
* :mod:`mcbench.nn.losses` -- the training losses (L1 in log space, SMAPE, gradient L1);
* :mod:`mcbench.nn.crops` -- training crops from :mod:`mcbench.training_data` as tensors, the
  train/validation split, seeded augmented batches;
* :mod:`mcbench.nn.train` -- the seeded, resumable training loop with checkpoints, the optional
  adversarial critic, validation, and the weights + record it writes;
* :mod:`mcbench.nn.inference` -- loading a network's weights and running it, deterministically:
  the inference every learned plugin shares (``denoise_with_network``, ``combine_with_network``).

The weights' location and file format, the safe loader and :func:`mcbench.io.weights.is_learned_method`
are in the torch-free :mod:`mcbench.io.weights`.

A learned method is one module in ``methods/`` whose declaration
(:class:`mcbench.contracts.method.MethodSpec`) sets ``learned`` (a
:class:`mcbench.contracts.method.LearnedSpec`: ``network`` hyperparameters, ``training`` settings,
``build_network(**network)``); the network's ``forward`` takes a dict of raw buffers (see
:data:`mcbench.nn.crops.BUFFER_KEYS`) and returns linear HDR radiance (N, 3, H, W). Its weights
live in the weights folder (config key ``weights_dir``, default ``methods/weights``) as
``<name>.pt`` with a record ``<name>.json``. The functions here take the method's module or its
declaration and the weights file (core never imports ``methods``; callers resolve names with
``methods.load_method``), and torch is imported only by
this package's modules other than ``__init__``: a method module imports them inside
``build_network`` / ``denoise`` so that importing it (as parsing the DAG does) does not import torch.
"""
