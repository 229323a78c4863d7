import os

os.environ["MCBENCH_WEIGHTS_DIR"] = os.path.abspath(snakemake.params.weights_dir)

from mcbench.logs import run_logged  # noqa: E402
from mcbench.nn.train import train_network  # noqa: E402
from mcbench.weights import check_learned_method  # noqa: E402
from methods import load_method  # noqa: E402


def train_named_network(name, *args, **kwargs):
    """Resolve ``methods/<name>.py`` (here, not in core: core never imports methods) and train it."""
    module = check_learned_method(load_method(name, kind="denoiser", config_key=f"network '{name}'"))
    return train_network(module, *args, **kwargs)


run_logged(snakemake.log[0], train_named_network, snakemake.wildcards.network, list(snakemake.input),
           snakemake.output.weights, snakemake.output.record, snakemake.params.checkpoint,
           {**snakemake.params.overrides, "threads": snakemake.threads},
           log=lambda message: print(message, flush=True))
