"""Layer ``pipeline``: the work behind each Snakemake rule, as plain functions of paths and params.

One module per ``workflow/rules/X.smk`` (``mcbench.pipeline.X``); ``workflow/scripts/*`` unpack
the ``snakemake`` object and call only this layer. Beside them: :mod:`~mcbench.pipeline.config`
(the schema and its defaults), :mod:`~mcbench.pipeline.plan` (what the rules plan from a config,
with every parse-time check), :mod:`~mcbench.pipeline.threads` (a job's thread pools held to its
``threads``), :mod:`~mcbench.pipeline.resources` (cluster requests),
:mod:`~mcbench.pipeline.logs` (a step's output in its log) and
:mod:`~mcbench.pipeline.registry` (the one place that resolves method and scene names).
"""
