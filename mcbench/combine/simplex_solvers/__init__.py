"""Simplex-constrained least squares for the ensemble's weights (Zheng et al. 2021 Sec. 4.1,
5.2.1-5.2.3): batches of small problems, one per pixel-channel (or per pixel), each solved
independently (numba ``prange`` over chunks of problems). One module per solver family:

* :mod:`~mcbench.combine.simplex_solvers.problem` -- the objective (Eq. 25), the solver choices
  and the kernels the families share;
* :mod:`~mcbench.combine.simplex_solvers.iterative` -- the paper's iterative solver (Sec. 4.1)
  with its counter-based random numbers;
* :mod:`~mcbench.combine.simplex_solvers.exact` -- closed-form 2D geometry per pixel-channel,
  minimum-norm tie-break (mcbench's, not the paper's);
* :mod:`~mcbench.combine.simplex_solvers.shared_exact` -- one weight vector shared by the
  channels, Wolfe's minimum-norm-point algorithm (Sec. 5.2.3);
* :mod:`~mcbench.combine.simplex_solvers.unconstrained` -- sum w = 1 without w >= 0 (Sec. 5.2.1);
* :mod:`~mcbench.combine.simplex_solvers.qp` -- the general QP solver, the slow baseline of
  Fig. 6 (Sec. 5.2.2).

Each solver returns (P, N) float64 weights of P problems. All geometry is float64 (Eq. 29's c1
and the hull tests subtract nearly equal radiance values).
"""
