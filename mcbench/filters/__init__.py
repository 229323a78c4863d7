"""Layer ``filters``: image filters any method may use.

* :mod:`mcbench.filters.bilateral` -- the cross-bilateral filter (Zheng et al. 2021 Eq. 32-34);
* :mod:`mcbench.filters.blur_and_outliers` -- the smoothing passes the authors' public code puts
  around it: Gaussian blur, outlier removal, reflected borders;
* :mod:`mcbench.filters.nlmeans` -- non-local means with variance cancellation (Rousselle et al.
  2012);
* :mod:`mcbench.filters.sure` -- SURE of a denoised image, its divergence, and progressive
  denoising's mixing activation and t-test (Firmino et al. 2022).
"""
