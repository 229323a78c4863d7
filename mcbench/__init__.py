"""mcbench: the Python package behind the MC-denoiser benchmark (Zheng et al. 2021 and related).

The package is layered: each layer imports only the lower layers it is declared to use, never a
higher one. The declaration is the import-linter contracts of ``pyproject.toml``
(``[tool.importlinter]``, checked by ``lint-imports`` and ``tests/test_architecture.py``);
``docs/architecture.md`` draws the graph. Lowest first:

* ``mcbench`` itself: :class:`BenchError`, :mod:`mcbench.jit` (numba with an on-disk cache),
  :mod:`mcbench.progress` (progress lines of long jobs); every layer may use them;
* :mod:`mcbench.contracts` -- the plugins' declarations: a method's ``MethodSpec`` (a learned
  method's ``LearnedSpec``), a scene's ``SceneSpec``;
* :mod:`mcbench.io` -- EXR files, render buffers, tables and JSON records, network-weight files;
* :mod:`mcbench.filters` -- image filters any method may use: bilateral, NL-means, SURE;
* :mod:`mcbench.render` -- Mitsuba rendering, seeds, scene geometry, hair curves, variants;
* :mod:`mcbench.combine` -- per-pixel weighting of several images: simplex solvers,
  ``solve_weights``, the weight filter, blending, MSE estimates and one-hot selection, the
  ground-truth-statistics (oracle) weights;
* :mod:`mcbench.nn` -- the networks' shared training and inference machinery (torch);
* :mod:`mcbench.training_data` -- procedural training scenes rendered into crops;
* :mod:`mcbench.analysis` -- tables in, tables and figures out: metrics, ranking, the pool, the
  study, comparisons, figures, the viewer, the scene summary;
* :mod:`mcbench.pipeline` -- the work behind each Snakemake rule (one module per
  ``workflow/rules/X.smk``, named for it unless a lower layer has a module of that name), the
  config and its plan, cluster resources, thread limits and logs. Only this layer resolves
  method and scene names (through the registries ``methods`` and ``scenes``).

The plugins (``methods/``, ``scenes/``) import the layers the graph declares for them, never
``pipeline``.
"""

__all__ = ["BenchError", "NOISY", "NOISY_LABEL", "METRICS_COLUMNS"]

#: The noisy input's row in every table (metrics, rankings, timings); no method may take the name.
NOISY = "noisy"
#: ... and its label in tables and figures.
NOISY_LABEL = "Noisy input"
#: The columns of a metrics table (a case's ``results/metrics/<scene>/spp<N>.csv`` and the gathered
#: ``results/metrics.csv``): one row per entry (the noisy input or a candidate) and metric.
METRICS_COLUMNS = ("scene", "spp", "entry", "metric", "value")


class BenchError(RuntimeError):
    """An error the user can fix: the message names the offending file or config key."""
