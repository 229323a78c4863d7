"""relMSE corrected for the reference's own Monte Carlo noise, from the reference's stored
variance of the mean (:func:`mcbench.analysis.metrics.relmse_corrected`); no map."""

from mcbench.analysis.metrics import relmse_corrected
from mcbench.contracts.metric import MetricSpec

METRIC = MetricSpec(name="relmse_corrected", label="relMSE (reference-noise corrected)", value=relmse_corrected,
                    reads_reference_variance=True)
