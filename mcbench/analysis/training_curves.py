"""The learned networks' validation curves, from their training records (each trained
until its validation loss stops improving, its curve in docs/).

    python -m mcbench.analysis.training_curves WEIGHTS_DIR [--out docs/training.md] [--compare OTHER_DIR]

A record (``<name>.json`` beside ``<name>.pt``, written by :func:`mcbench.nn.train.train_network`)
holds ``history``: one entry per validation, ``{"step", "round", "train_loss",
"validation_loss", "validation_relmse", "seconds"}``. The page gives, per network, the machine
(the CPU model of ``cpu``, the torch threads), the stopping rule's outcome (``steps_run``,
``rounds_run``, ``stopped_by``), the round kept (lowest validation loss at a round's end) and the
table of validations; with ``--out`` it writes the page and one PNG per network beside it
(``<out stem>/<name>.png``: validation loss and relMSE against the step, rounds marked).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from mcbench.io.tables import read_json

__all__ = ["kept_round", "network_section", "summary_table", "training_page", "write_curve"]


def kept_round(history: list[dict], steps: int) -> dict | None:
    """The validation at the end of the round whose weights were kept: the lowest validation loss
    among the entries at a multiple of ``steps`` (the first of equals, as the trainer keeps it);
    None when no round ended."""
    ends = [entry for entry in history if steps and entry["step"] % steps == 0]
    return min(ends, key=lambda entry: entry["validation_loss"]) if ends else None


def _cpu(record: dict) -> str:
    """The record's CPU: its model name, with family, model number and AVX-512 when recorded (a
    virtual machine may name its CPU only "AMD EPYC", which several generations share)."""
    cpu = record.get("cpu") or {}
    model = cpu.get("model") if isinstance(cpu, dict) else None
    if not model:
        return f"not recorded ({record.get('machine', 'unknown machine')})"
    details = [f"family {cpu['family']} model {cpu['model_number']}"] if cpu.get("family") and cpu.get("model_number") else []
    if "avx512f" in cpu:
        details.append("AVX-512" if cpu["avx512f"] else "no AVX-512")
    return f"{model} ({', '.join(details)})" if details else model


def _number(value, digits: int = 5) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    return f"{value:.{digits}g}"


def network_section(name: str, record: dict, *, image: str | None = None) -> list[str]:
    """Markdown lines of one network's record: what it was trained on and how long, the stopping
    rule's outcome and its validation table (``image``: the curve's path relative to the page)."""
    settings = record.get("settings", {})
    steps = int(settings.get("steps", 0))
    history = record.get("history", [])
    kept = kept_round(history, steps)
    lines = [f"## {record.get('label', name)} (`{name}`)", ""]
    features = record.get("data", {}).get("features", "first_hit (not recorded)")
    lines.append(f"- features: {features}; loss {record.get('loss')}; {settings.get('rounds', 1)} round(s) at most "
                 f"of {steps} steps, plateau {settings.get('plateau', '—')}")
    lines.append(f"- ran {record.get('steps_run', steps)} steps in {record.get('rounds_run', 1)} round(s), stopped by "
                 f"{record.get('stopped_by', 'its fixed step count')}; kept: "
                 + (f"round {kept['step'] // steps} (validation loss {_number(kept['validation_loss'])})" if kept else "—"))
    lines.append(f"- {record.get('seconds', float('nan')) / 60:.1f} minutes on {record.get('threads', '?')} torch "
                 f"thread(s) of {_cpu(record)}")
    if image:
        lines += ["", f"![{name}]({image})"]
    lines += ["", "| step | round | training loss | validation loss | validation relMSE |",
              "|---:|---:|---:|---:|---:|"]
    for entry in history:
        mark = " (kept)" if entry is kept else ""
        lines.append(f"| {entry['step']} | {entry.get('round', '—')} | {_number(entry.get('train_loss'))} | "
                     f"{_number(entry['validation_loss'])}{mark} | {_number(entry.get('validation_relmse'))} |")
    return lines + [""]


def _inputs_loss(per_spp: dict) -> str:
    """A combiner's inputs' validation loss (``correlated_loss``), the mean over the levels as the
    record's own loss is over its equal number of crops per level; "—" for a network without inputs."""
    values = [entry["correlated_loss"] for entry in per_spp.values() if "correlated_loss" in entry]
    return _number(sum(values) / len(values), 4) if values and len(values) == len(per_spp) else "—"


def summary_table(records: dict[str, dict], *, compare: dict[str, dict] | None = None,
                  levels: tuple[str, ...] = ("4", "16", "1024")) -> list[str]:
    """Markdown lines of one row per network of ``records`` (name -> record): its features, rounds
    run, steps, minutes and torch threads, its validation loss (a combiner's: beside its inputs' on
    the same crops, :func:`_inputs_loss`) and its validation relMSE at
    ``levels`` spp (the noisy input's in parentheses); with ``compare`` (name -> record of the same
    networks trained otherwise, e.g. on the other feature convention) that record's validation loss
    beside it. Rendered by the same code, the validation crops of the two feature conventions hold
    the same colour and targets (the features alone differ), so their losses compare; records made
    by older code may hold other samples of the same scenes (the committed first-hit base networks':
    the noisy input's loss agrees to 0.5 % at every level, its outlier-driven relMSE to 45 %), so
    compare the noisy input's per-level values in the records first."""
    header = ["network", "features", "rounds (stopped by)", "steps", "minutes", "threads", "validation loss",
              "its inputs' loss"]
    if compare is not None:
        header.append("compared: validation loss")
    header.append(f"validation relMSE at {' / '.join(levels)} spp (noisy)")
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for name, record in records.items():
        per_spp = record.get("validation", {}).get("per_spp", {})
        relmse = " / ".join(f"{_number(per_spp[l]['relmse'], 3)} ({_number(per_spp[l]['noisy_relmse'], 3)})"
                            if l in per_spp else "—" for l in levels)
        row = [f"`{name}`", str(record.get("data", {}).get("features", "first_hit")),
               f"{record.get('rounds_run', 1)} ({record.get('stopped_by', 'fixed count')})",
               str(record.get("steps_run", record.get("settings", {}).get("steps", "—"))),
               f"{record.get('seconds', float('nan')) / 60:.0f}", str(record.get("threads", "?")),
               _number(record.get("validation", {}).get("loss"), 4), _inputs_loss(per_spp)]
        if compare is not None:
            other = compare.get(name)
            row.append(_number(other.get("validation", {}).get("loss"), 4) if other else "—")
        lines.append("| " + " | ".join(row + [relmse]) + " |")
    return lines


def write_curve(path: str | Path, name: str, record: dict) -> None:
    """A PNG of ``record``'s validation loss and relMSE against the step, the rounds' ends dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    history = record.get("history", [])
    steps = int(record.get("settings", {}).get("steps", 0))
    figure, loss_axis = plt.subplots(figsize=(6, 3.2))
    x = [entry["step"] for entry in history]
    loss_axis.plot(x, [entry["validation_loss"] for entry in history], "o-", label=f"validation {record.get('loss')}")
    loss_axis.set_xlabel("step")
    loss_axis.set_ylabel(f"validation {record.get('loss')}")
    relmse_axis = loss_axis.twinx()
    relmse_axis.plot(x, [entry.get("validation_relmse", float("nan")) for entry in history], "s--", color="tab:orange",
                     label="validation relMSE")
    relmse_axis.set_ylabel("validation relMSE")
    for end in range(steps, (max(x) if x else 0) + 1, steps or 1):
        loss_axis.axvline(end, color="grey", linestyle=":", linewidth=1)
    loss_axis.set_title(record.get("label", name), fontsize=9)
    figure.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=100)
    plt.close(figure)


def training_page(weights_dir: str | Path, *, images: Path | None = None, relative_to: Path | None = None,
                  out: Path | None = None, compare: str | Path | None = None) -> str:
    """The Markdown page of every training record in ``weights_dir`` (sorted by name): a summary
    table (:func:`summary_table`, with the records of the same names in ``compare`` when given), then
    each network's section, with a curve per network written into ``images`` (linked relative to
    ``relative_to``) when given; ``out``: the page's path, named in the command it gives."""
    folder = Path(weights_dir)
    paths = sorted(folder.glob("*.json"))
    if not paths:
        raise ValueError(f"{folder}: no training records (<name>.json); train the networks first")
    records = {path.stem: read_json(path) for path in paths}
    compared = None
    if compare is not None:
        compared = {path.stem: read_json(path) for path in sorted(Path(compare).glob("*.json"))}
        if not compared:
            raise ValueError(f"{compare}: no training records (<name>.json) to compare with")
    command = (f"python -m mcbench.analysis.training_curves {folder}" + (f" --out {out}" if out else "")
               + (f" --compare {compare}" if compare is not None else ""))
    lines = ["# Training records and validation curves", "",
             f"Generated from the records in `{folder}` by `{command}`"
             + (f"; compared: the records in `{compare}`" if compare is not None else "") + ".", ""]
    lines += summary_table(records, compare=compared) + [""]
    for path in paths:
        record = records[path.stem]
        image = None
        if images is not None:
            write_curve(images / f"{path.stem}.png", path.stem, record)
            image = str((images / f"{path.stem}.png").relative_to(relative_to)) if relative_to else str(images)
        lines += network_section(path.stem, record, image=image)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m mcbench.analysis.training_curves",
                                     description="Validation curves of the training records in a weights folder.")
    parser.add_argument("weights_dir")
    parser.add_argument("--out", default=None, help="write the page here, its curves in <out stem>/ (default: print)")
    parser.add_argument("--compare", default=None,
                        help="a second weights folder whose networks' validation losses the summary gives beside")
    args = parser.parse_args(argv)
    if args.out is None:
        print(training_page(args.weights_dir, compare=args.compare))
        return 0
    out = Path(args.out)
    text = training_page(args.weights_dir, images=out.parent / out.stem, relative_to=out.parent, out=out,
                         compare=args.compare)
    out.write_text(text + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
