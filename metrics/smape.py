"""SMAPE: mean of |y - r| / (|y| + |r| + 0.01) on linear HDR values (Vogels et al. 2018)."""

from mcbench.analysis.metrics import smape
from mcbench.contracts.metric import MetricSpec

METRIC = MetricSpec(name="smape", label="SMAPE", value=smape)
