"""Which validation crops carry a learned base network's relMSE: the worst (crop, level) items.

    python tools/validation_outliers.py wskpn [--weights-dir methods/weights] [--crops results/training]
                                              [--spp 4] [--top 5]

Runs the committed network on the validation crops of its record (``data.validation_scenes``, the
files ``<crops>/example_<seed>_<k>.exr`` that ``snakemake training_data`` writes with the record's
settings) and prints, for the items at ``--spp``: the mean relMSE (``mcbench.nn.losses.relmse``, the
record's ``validation.per_spp`` value), the mean without the worst item, and the ``--top`` worst
items with their noisy input's relMSE and the pixel of largest error (output, reference, noisy
colour, albedo). Base networks only (a combiner's crops need its bases' results). Writes nothing.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mcbench.analysis.metrics import relmse_map  # noqa: E402
from mcbench.io.tables import read_json  # noqa: E402
from mcbench.io.weights import record_path, weights_path  # noqa: E402
from mcbench.nn.crops import load_crops, validation_batches  # noqa: E402
from mcbench.nn.inference import load_network  # noqa: E402
from mcbench.nn.losses import relmse  # noqa: E402
from methods import load_method  # noqa: E402


def item_errors(network, crops, spp: int) -> list[dict]:
    """One dict per validation item at ``spp``: seed, relMSE of the output and of the noisy input,
    and the pixel of largest per-pixel relMSE with its values."""
    items = []
    with torch.no_grad():
        for buffers, targets, seeds, levels in validation_batches(crops, 16):
            output = network(buffers)
            for i in np.flatnonzero(np.asarray(levels) == spp):
                y, t = output[i], targets[i]
                per_pixel = relmse_map(y.permute(1, 2, 0).double().numpy(), t.permute(1, 2, 0).double().numpy())
                row, col = np.unravel_index(int(np.argmax(per_pixel)), per_pixel.shape)
                items.append({
                    "seed": int(seeds[i]), "relmse": float(relmse(y[None], t[None])),
                    "noisy_relmse": float(relmse(buffers["color"][i:i + 1], t[None])),
                    "pixel": (int(row), int(col)), "pixel_relmse": float(per_pixel[row, col]),
                    **{key: np.round(tensor[:, row, col].double().numpy(), 4).tolist() for key, tensor in
                       (("output", y), ("reference", t), ("noisy", buffers["color"][i]), ("albedo", buffers["albedo"][i]))}})
    return sorted(items, key=lambda item: -item["relmse"])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("network")
    parser.add_argument("--weights-dir", default="methods/weights")
    parser.add_argument("--crops", default="results/training")
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--top", type=int, default=5)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    record = read_json(record_path(args.weights_dir, args.network))
    seeds = record["data"]["validation_scenes"]
    files = sorted(path for seed in seeds for path in Path(args.crops).glob(f"example_{seed}_*.exr"))
    if not files:
        raise SystemExit(f"no crops of the validation scenes {seeds} in {args.crops}: run "
                         "`snakemake --cores 2 training_data` with the record's training settings")
    network = load_network(load_method(args.network).METHOD, weights_path(args.weights_dir, args.network))
    items = item_errors(network, load_crops(files), args.spp)
    if not items:
        raise SystemExit(f"no validation item at {args.spp} spp (levels: {record['data']['spp_levels']})")
    values = np.array([item["relmse"] for item in items])
    print(f"{args.network} ({args.weights_dir}), {len(items)} validation items at {args.spp} spp: mean relMSE "
          f"{values.mean():.4g}, without the worst {values[1:].mean() if len(values) > 1 else float('nan'):.4g}")
    for item in items[:args.top]:
        print(f"- scene {item['seed']}: relMSE {item['relmse']:.4g} (noisy {item['noisy_relmse']:.4g}); pixel "
              f"{item['pixel']} relMSE {item['pixel_relmse']:.4g}: output {item['output']}, reference "
              f"{item['reference']}, noisy {item['noisy']}, albedo {item['albedo']}")


if __name__ == "__main__":
    main()
