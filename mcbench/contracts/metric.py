"""The metric plugin contract: one typed declaration, :class:`MetricSpec`, that every
``metrics/<name>.py`` exports as its module-level ``METRIC``.

A metric is an error of an entry's image against the reference: its name (the config's and the
tables' ``metric`` column), its label (tables, captions, the viewer), the direction of better
values, the function computing its value, and optionally a per-pixel map the viewer draws with
its colour scale (:class:`ColourScale`). Constructing a declaration checks the names (a misspelt
field is refused with the closest known name) and every field's value; the registry
(``metrics/__init__.py``) reads ``METRIC`` and checks that its name is its file's. Importing this
module imports no plugin and no layer of ``mcbench``.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import re
from dataclasses import dataclass
from typing import Callable, Optional

from mcbench import BenchError

__all__ = ["SPEC_ATTRIBUTE", "ColourScale", "MetricSpec", "MetricSpecError", "check_metric_fields"]

#: The module-level name of a metric plugin's declaration.
SPEC_ATTRIBUTE = "METRIC"
#: What a metric's name may be: a wildcard of the rules and a column value of the tables.
NAME_PATTERN = re.compile(r"[a-z][a-z0-9_]*")


class MetricSpecError(BenchError):
    """A :class:`MetricSpec` (or its :class:`ColourScale`) with an unknown field or a bad value."""


@dataclass(frozen=True)
class ColourScale:
    """A fixed value range drawn with a matplotlib colour map, linear or log10.

    ``low``/``high``: the values at the ends of the map; values outside are clamped to the end
    colours (saturation, not wrap-around). ``log``: positions are log10(value) between
    log10(low) and log10(high) (``low > 0``).
    """

    name: str
    colormap: str
    low: float
    high: float
    log: bool
    description: str


@dataclass(frozen=True, kw_only=True, eq=False)
class MetricSpec:
    """What a metric module declares (``METRIC = MetricSpec(...)``); fields, keyword-only:

    * ``name`` -- the metric's name: its file ``metrics/<name>.py``, its config entry under
      ``metrics:``, the ``metric`` column of the tables and the ``{metric}`` of file names.
    * ``label`` -- how tables, captions and the viewer name it (e.g. ``"relMSE"``).
    * ``value`` -- ``f(image, reference) -> float`` (both (H, W, 3) linear radiance), or
      ``f(image, reference, reference_variance) -> float`` when ``reads_reference_variance``.
    * ``lower_is_better`` -- True for an error (every table scores lower values better).
    * ``reads_reference_variance`` -- ``value`` also takes the reference's per-pixel variance of
      the mean (the references' ``variance`` layer); a study whose references lack it refuses it.
    * ``error_map`` -- ``f(image, reference) -> (H, W)`` per-pixel values the viewer draws, or
      None (no map).
    * ``map_scale`` -- the :class:`ColourScale` of the map (set exactly when ``error_map`` is).
    * ``value_and_map`` -- optional ``f(image, reference) -> (map, value)`` computing both in one
      evaluation (an expensive metric whose value is a reduction of its map); used instead of
      ``value`` and ``error_map`` when both are needed.
    """

    name: str
    label: str
    value: Callable
    lower_is_better: bool = True
    reads_reference_variance: bool = False
    error_map: Optional[Callable] = None
    map_scale: Optional[ColourScale] = None
    value_and_map: Optional[Callable] = None

    def __post_init__(self) -> None:
        check_metric_fields(self)


@functools.cache
def field_names() -> tuple[str, ...]:
    """The fields of :class:`MetricSpec`, in declaration order."""
    return tuple(f.name for f in dataclasses.fields(MetricSpec))


def _closest(key: str) -> str:
    close = difflib.get_close_matches(key.lower(), field_names(), n=1)
    return f" (did you mean '{close[0]}'?)" if close else ""


def _refuse_unknown_fields(init: Callable) -> Callable:
    """``MetricSpec.__init__`` that first refuses a keyword that is no field, naming the closest one."""
    @functools.wraps(init)
    def checked_init(self, *args, **fields):
        unknown = [key for key in fields if key not in field_names()]
        if unknown:
            raise MetricSpecError("; ".join(f"MetricSpec has no field '{key}'{_closest(key)}" for key in unknown))
        init(self, *args, **fields)
    return checked_init


MetricSpec.__init__ = _refuse_unknown_fields(MetricSpec.__init__)

#: Each field's check and the type it names in an error.
_FIELD_CHECKS = {
    "name": (lambda v: isinstance(v, str) and NAME_PATTERN.fullmatch(v) is not None,
             "a str of lower-case letters, digits and '_', starting with a letter"),
    "label": (lambda v: isinstance(v, str) and v.strip() != "", "a non-empty str"),
    "value": (callable, "a function"),
    "lower_is_better": (lambda v: isinstance(v, bool), "bool"),
    "reads_reference_variance": (lambda v: isinstance(v, bool), "bool"),
    "error_map": (lambda v: v is None or callable(v), "a function or None"),
    "map_scale": (lambda v: v is None or isinstance(v, ColourScale), "a ColourScale or None"),
    "value_and_map": (lambda v: v is None or callable(v), "a function or None"),
}


def check_metric_fields(spec: MetricSpec) -> None:
    """Refuse a declaration whose fields do not fit their types or each other: a
    :class:`MetricSpecError` naming the field (e.g. ``MetricSpec field 'lower_is_better' must be
    bool, got 'yes'``)."""
    for name, (fits, expected) in _FIELD_CHECKS.items():
        value = getattr(spec, name)
        if not fits(value):
            raise MetricSpecError(f"MetricSpec field '{name}' must be {expected}, got {value!r}")
    if (spec.error_map is None) != (spec.map_scale is None):
        raise MetricSpecError("MetricSpec fields 'error_map' and 'map_scale' go together: set both or neither")
    if spec.value_and_map is not None and spec.error_map is None:
        raise MetricSpecError("MetricSpec field 'value_and_map' needs 'error_map' (and 'map_scale')")
    if spec.error_map is not None and spec.reads_reference_variance:
        raise MetricSpecError("MetricSpec field 'error_map' is f(image, reference): a metric that reads the "
                              "reference's variance has no map (set error_map=None)")
    if spec.map_scale is not None and spec.map_scale.name != spec.name:
        raise MetricSpecError(f"MetricSpec field 'map_scale' is named '{spec.map_scale.name}'; a metric's "
                              f"scale takes the metric's name '{spec.name}'")
