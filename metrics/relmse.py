"""relMSE: mean over pixels and channels of (y - r)² / (r² + 0.01) (Rousselle et al. 2011, as
Zheng et al. 2021 Sec. 5.3.2 use it), with its per-pixel map in the viewer."""

from mcbench.analysis.metrics import relmse, relmse_map
from mcbench.analysis.viewer_images import RELMSE_SCALE
from mcbench.contracts.metric import MetricSpec

METRIC = MetricSpec(name="relmse", label="relMSE", value=relmse, error_map=relmse_map, map_scale=RELMSE_SCALE)
