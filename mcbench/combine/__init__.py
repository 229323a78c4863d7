"""Layer ``combine``: per-pixel weighting of several images of one case.

* :mod:`mcbench.combine.selection` -- dual-buffer MSE estimates, their prefilters and one-hot
  selection (Zheng et al. 2021 Sec. 5.2.6);
* :mod:`mcbench.combine.oracle` -- weights from ground-truth statistics (Sec. 5.2.7).
"""
