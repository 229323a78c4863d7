"""HDR-FLIP (Andersson et al. 2021, NVIDIA's flip-evaluator): the mean of its per-pixel map, the
map drawn by the viewer; one evaluation gives both (``value_and_map``)."""

from mcbench.analysis.metrics import flip, flip_map, flip_with_map
from mcbench.analysis.viewer_images import FLIP_SCALE
from mcbench.contracts.metric import MetricSpec

METRIC = MetricSpec(name="flip", label="HDR-FLIP", value=flip, error_map=flip_map, map_scale=FLIP_SCALE,
                    value_and_map=flip_with_map)
