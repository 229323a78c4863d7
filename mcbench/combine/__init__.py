"""Layer ``combine``: per-pixel weighting of several images of one case.

* :mod:`mcbench.combine.simplex_solvers` -- batches of small simplex-constrained least-squares
  problems: the ensemble's solvers (Zheng et al. 2021 Sec. 4.1, 5.2.1-5.2.3), one module per family;
* :mod:`mcbench.combine.ensemble_weights` -- the ensemble's raw weights of an image or a block of
  rows (``solve_weights``), its options' choices, defaults and checks;
* :mod:`mcbench.combine.weight_filter` -- the cross-bilateral filter of weight maps (Sec. 4.2) and
  the public code's passes around it;
* :mod:`mcbench.combine.blending` -- weighted sums of the images (Eq. 3 / 35);
* :mod:`mcbench.combine.ensemble_driver` -- the ensemble of a render in one pass of bands of rows
  (solve, filter, blend), the driver of the ``ensemble`` combiner;
* :mod:`mcbench.combine.selection` -- dual-buffer MSE estimates, their prefilters and one-hot
  selection (Sec. 5.2.6);
* :mod:`mcbench.combine.oracle_weights` -- weights from ground-truth statistics (Sec. 5.2.7).
"""
