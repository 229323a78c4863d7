"""The one place in ``mcbench`` that resolves method, scene and metric names: the registries of
the plugin packages ``methods/``, ``scenes/`` and ``metrics/``, re-exported for the rules and the
pipeline steps.

A name from a config is resolved here (or by the rules through this module); every layer below
the pipeline takes a method or scene *module* or a metric's declaration, never a name, so the
core imports no plugin.
The plugins are imported when a function is called, not when this module is imported.
"""

from __future__ import annotations

from types import ModuleType
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    from mcbench.contracts.metric import MetricSpec

__all__ = ["available_methods", "load_method", "method_parameters", "config_method_table", "single_image_function",
           "available_scenes", "load_scene", "available_metrics", "load_metric", "load_metrics", "metric_source"]


def available_methods() -> list[str]:
    """The method modules in ``methods/`` (:func:`methods.available_methods`)."""
    import methods

    return methods.available_methods()


def load_method(name: str, kind: str | None = None, config_key: str = "config") -> ModuleType:
    """``methods/<name>.py`` checked against the contract of ``kind`` (:func:`methods.load_method`);
    an unknown name is an error naming ``config_key``."""
    import methods

    return methods.load_method(name, kind, config_key)


def method_parameters(module: ModuleType) -> dict:
    """A method module's config parameters (:func:`methods.method_parameters`)."""
    import methods

    return methods.method_parameters(module)


def config_method_table(config: dict, *, is_learned: Callable[[ModuleType], bool]) -> dict:
    """The candidate table of a resolved config (:func:`methods.config_method_table`)."""
    import methods

    return methods.config_method_table(config, is_learned=is_learned)


def single_image_function(name: str, *, choices=None) -> Callable:
    """Base denoiser ``name`` as a function of one image (:func:`methods.single_image_function`)."""
    import methods

    return methods.single_image_function(name, choices=choices)


def available_scenes() -> list[str]:
    """The scene modules in ``scenes/`` (:func:`scenes.available_scenes`)."""
    import scenes

    return scenes.available_scenes()


def load_scene(name: str, config_key: str = "scenes") -> ModuleType:
    """``scenes/<name>.py`` checked against the scene contract (:func:`scenes.load_scene`); an
    unknown name is an error naming ``config_key``."""
    import scenes

    return scenes.load_scene(name, config_key=config_key)


def available_metrics() -> list[str]:
    """The metric modules in ``metrics/`` (:func:`metrics.available_metrics`)."""
    import metrics

    return metrics.available_metrics()


def load_metric(name: str, config_key: str = "metrics") -> MetricSpec:
    """The declaration of ``metrics/<name>.py`` (:func:`metrics.load_metric`); an unknown name is an
    error naming ``config_key`` and the closest metric."""
    import metrics

    return metrics.load_metric(name, config_key=config_key)


def load_metrics(names, config_key: str = "metrics") -> dict[str, MetricSpec]:
    """{name: declaration} of the metrics ``names`` in their order; errors name ``config_key[i]``."""
    return {name: load_metric(name, config_key=f"{config_key}[{index}]") for index, name in enumerate(names)}


def metric_source(name: str) -> bytes:
    """The source of ``metrics/<name>.py`` (what the metric's kept values are keyed by, beside
    the numerics of :mod:`mcbench.analysis.metrics`)."""
    import sys
    from pathlib import Path

    load_metric(name)
    return Path(sys.modules[f"metrics.{name}"].__file__).read_bytes()
