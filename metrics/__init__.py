"""Metric registry: one module per metric.

A metric module declares itself in one module-level object, ``METRIC``, a
:class:`mcbench.contracts.metric.MetricSpec` (name, label, direction, the value function, and
optionally a per-pixel map with its colour scale), e.g.::

    METRIC = MetricSpec(name="smape", label="SMAPE", value=smape)

:func:`load_metric` refuses a name with no module here (naming the config key and the closest
name), a module without a declaration, and a declaration whose name is not its file's; a
misspelt field or a bad value is refused when the declaration is built (each error names
``metrics/<name>.py``). The numerics a test or a second module shares live in
:mod:`mcbench.analysis.metrics`; a metric used nowhere else may hold its code in its file.

Adding a metric is one new file here plus its name under ``metrics:`` in the config.
"""

from __future__ import annotations

import difflib
import importlib
import pkgutil

from mcbench import BenchError
from mcbench.contracts.metric import SPEC_ATTRIBUTE, MetricSpec, MetricSpecError

__all__ = ["UnknownMetricError", "available_metrics", "load_metric"]


class UnknownMetricError(BenchError):
    """A config key names a metric that has no module in ``metrics/``, or a broken one."""


def available_metrics() -> list[str]:
    """Names of the metric modules in this package."""
    return sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))


def load_metric(name: str, config_key: str = "metrics") -> MetricSpec:
    """The declaration ``METRIC`` of ``metrics/<name>.py``, checked.

    ``config_key`` is named in the error (e.g. ``"metrics[2]"``), with the closest available
    name, so a typo in the config is reported where it is.
    """
    available = available_metrics()
    if name not in available:
        close = difflib.get_close_matches(str(name), available, n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise UnknownMetricError(f"{config_key}: unknown metric '{name}'{hint}; available: {', '.join(available)} "
                                 f"(a metric is a file metrics/<name>.py)")
    try:
        module = importlib.import_module(f"{__name__}.{name}")
    except MetricSpecError as exc:       # raised by the declaration while the module imports
        raise UnknownMetricError(f"{config_key}: metrics/{name}.py: {exc}") from None
    spec = getattr(module, SPEC_ATTRIBUTE, None)
    if not isinstance(spec, MetricSpec):
        raise UnknownMetricError(f"{config_key}: metrics/{name}.py declares no {SPEC_ATTRIBUTE} = MetricSpec(...)")
    if spec.name != name:
        raise UnknownMetricError(f"{config_key}: metrics/{name}.py declares the metric '{spec.name}'; its name must "
                                 f"be its file's, '{name}'")
    return spec
