"""DSSIM: 1 - SSIM of the tone-mapped images (Zheng et al. 2021 Sec. 5.3.2)."""

from mcbench.analysis.metrics import dssim
from mcbench.contracts.metric import MetricSpec

METRIC = MetricSpec(name="dssim", label="DSSIM", value=dssim)
