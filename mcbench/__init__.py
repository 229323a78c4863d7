"""mcbench: the Python package behind the MC-denoiser benchmark (Zheng et al. 2021 and related).

The package is layered; a module imports only from its own layer or a lower one, never from a
higher one (``tests/test_architecture.py`` checks it; ``docs/architecture.md`` draws it). Lowest
first (:data:`LAYERS`):

* ``mcbench`` itself: :class:`BenchError`, :mod:`mcbench.jit` (numba with an on-disk cache),
  :mod:`mcbench.progress` (progress lines of long jobs);
* :mod:`mcbench.io` -- EXR files, render buffers, tables and JSON records, network-weight files,
  the method plugin contract (:mod:`mcbench.io.method_spec`);
* :mod:`mcbench.render` -- Mitsuba rendering, seeds, scene geometry, hair curves, variants;
* :mod:`mcbench.filters` -- image filters any method may use: bilateral, NL-means, SURE;
* :mod:`mcbench.combine` -- per-pixel weighting of several images: simplex solvers,
  ``solve_weights``, the weight filter, blending, MSE estimates and one-hot selection, the
  ground-truth-statistics (oracle) weights;
* :mod:`mcbench.nn` -- the networks' shared training and inference machinery (torch);
* :mod:`mcbench.training_data` -- procedural training scenes rendered into crops;
* :mod:`mcbench.analysis` -- tables in, tables and figures out: metrics, ranking, the pool, the
  study, comparisons, figures, the viewer, reports;
* :mod:`mcbench.pipeline` -- the work behind each Snakemake rule (one module per
  ``workflow/rules/X.smk``), the config, cluster resources and logs. Only this layer resolves
  method and scene names (through the registries ``methods`` and ``scenes``).

The plugins (``methods/``, ``scenes/``) may import any layer but ``pipeline``.
"""

__all__ = ["BenchError", "LAYERS", "NOISY", "NOISY_LABEL"]

#: The package's layers, lowest first: a module of layer i imports only from layers <= i (and
#: from the top-level modules of ``mcbench``, which sit below every layer).
LAYERS = ("io", "render", "filters", "combine", "nn", "training_data", "analysis", "pipeline")

#: The noisy input's row in every table (metrics, rankings, timings); no method may take the name.
NOISY = "noisy"
#: ... and its label in tables and figures.
NOISY_LABEL = "Noisy input"


class BenchError(RuntimeError):
    """An error the user can fix: the message names the offending file or config key."""
