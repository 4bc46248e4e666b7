"""`semloc train-descriptor` (VoxNet, SVL, FCGF-style; needs torch) and `semloc descriptors-eval`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from semloc.association import DESCRIBERS
from semloc.cli.app import MAX_SEED, app, choices, console, with_default
from semloc.cli.extras import need
from semloc.cli.files import check_separate
from semloc.descriptors import fcgf, svl
from semloc.descriptors.voxnet import WEIGHTS_FILE, load_weights
from semloc.eval.descriptors.evaluate import EvalConfig, print_report, run_evaluation, write_report
from semloc.eval.descriptors.train import TrainConfig, save_weights, train
from semloc.eval.descriptors.train_fcgf import FcgfTrainConfig
from semloc.eval.descriptors.train_fcgf import train as train_fcgf
from semloc.eval.descriptors.train_svl import SvlTrainConfig
from semloc.eval.descriptors.train_svl import train as train_svl

DescriptorChoice = choices("DescriptorChoice", [*DESCRIBERS, "both"])


TRAINED = ("voxnet", "svl", "fcgf-dense")
TrainedChoice = choices("TrainedChoice", TRAINED)
DEFAULT_OUT = {"voxnet": "voxnet_weights.npz", "svl": "svl_weights.npz",
               "fcgf-dense": "fcgf_weights.npz"}  # fmt: skip


@app.command("train-descriptor")
def train_descriptor(
    kind: Annotated[
        TrainedChoice,
        typer.Option(help="voxnet: the shape descriptor; svl, fcgf-dense: the baselines' models."),
    ] = TrainedChoice["voxnet"],
    out: Annotated[
        Path | None,
        typer.Option(
            "--output",
            "-o",
            help=with_default("Weights file to write (.npz).", "<kind>_weights.npz"),
        ),
    ] = None,
    seed: Annotated[
        int,
        typer.Option(min=0, max=MAX_SEED, help="Seed of the data, the initialisation and batches."),
    ] = 0,
    epochs: Annotated[
        int | None,
        typer.Option(min=1, max=1000, help=with_default("Training epochs.", "6, svl 10, fcgf 10")),
    ] = None,
    views: Annotated[
        int, typer.Option(min=6, max=10_000, help="voxnet: partial views per training instance.")
    ] = 48,
    full_views: Annotated[
        int,
        typer.Option(
            min=2, max=10_000, help="voxnet: whole-surface (CAD-style) views per instance."
        ),
    ] = 12,
    batches: Annotated[
        int | None,
        typer.Option(
            min=1, max=100_000, help=with_default("Batches per epoch.", "30, svl 60, fcgf 50")
        ),
    ] = None,
    worlds: Annotated[
        int,
        typer.Option(min=1, max=200, help="svl, fcgf-dense: simulated training worlds."),
    ] = 8,
    fixture: Annotated[
        Path | None,
        typer.Option(help="voxnet: also write test grids + torch embeddings (.npz)."),
    ] = None,
) -> None:
    """Train a learned model on simulated data (needs torch): the VoxNet shape descriptor
    (triplet loss), SVL's semantic-volume VAE or the FCGF-style dense features
    (hardest-contrastive loss).

    The defaults reproduce the shipped weights (src/semloc/descriptors/*_weights.npz).
    """
    out = out if out is not None else Path(DEFAULT_OUT[kind.value])
    check_separate({"--output": out, "--fixture": fixture}, {})
    need("train-descriptor", "train", "sim")
    trained = {"epochs": epochs, "batches_per_epoch": batches}
    trained = {k: v for k, v in trained.items() if v is not None}
    if kind.value == "voxnet":
        config = TrainConfig(seed=seed, views=views, full_views=full_views, **trained)
        weights, summary = train(config, log=console.print)
        shipped_file, load = WEIGHTS_FILE, load_weights
    elif kind.value == "svl":
        weights, summary = train_svl(SvlTrainConfig(seed=seed, worlds=worlds, **trained),
                                     log=console.print)  # fmt: skip
        shipped_file, load = svl.WEIGHTS_FILE, svl.load_weights
    else:
        weights, summary = train_fcgf(FcgfTrainConfig(seed=seed, worlds=worlds, **trained),
                                      log=console.print)  # fmt: skip
        shipped_file, load = fcgf.WEIGHTS_FILE, fcgf.load_weights
    save_weights(weights, out)
    size = out.stat().st_size / 1e6
    console.print(f"wrote {out} ({size:.2f} MB) in {summary['seconds']:.0f} s")
    if fixture is not None and "fixture" in summary:
        save_weights(summary["fixture"], fixture)
        console.print(f"wrote {fixture}")
    if shipped_file.exists() and out.resolve() != shipped_file.resolve():
        shipped = load()
        diff = max(float(np.abs(shipped[k] - weights[k]).max()) for k in weights)
        same = "identical to" if diff == 0 else f"max |diff| {diff:.2e} from"
        console.print(f"{same} the shipped weights")


@app.command("descriptors-eval")
def descriptors_eval(
    kind: Annotated[DescriptorChoice, typer.Option(help="Descriptor kind(s) to evaluate.")] = (
        DescriptorChoice["both"]
    ),
    out: Annotated[
        Path | None,
        typer.Option("--output", "-o", help="Folder for descriptors_eval.json and figures."),
    ] = None,
    seed: Annotated[
        int, typer.Option(min=0, max=MAX_SEED, help="Seed of the evaluation views.")
    ] = 1,
    views: Annotated[int, typer.Option(min=1, max=10_000, help="Partial views per instance.")] = 20,
    sequences: Annotated[
        int,
        typer.Option(
            min=0, max=1000, help="Simulated sequences for calibration and the gate effect."
        ),
    ] = 3,
    attempts: Annotated[
        int,
        typer.Option(min=1, max=10_000, help="Relocalization attempts per sequence and map kind."),
    ] = 8,
    window: Annotated[
        int, typer.Option(min=2, max=1000, help="Keyframes fused into the local map of an attempt.")
    ] = 6,
) -> None:
    """Retrieval (top-1/top-5) on held-out styles, the Scan2CAD check, δ and the gate's effect."""
    need("descriptors-eval", "sim")
    if out is not None:
        need("descriptors-eval", "viz", modules=("matplotlib",))
    kinds = list(DESCRIBERS) if kind.value == "both" else [kind.value]
    config = EvalConfig(
        kinds=kinds, seed=seed, views=views, sequences=sequences, attempts=attempts, window=window
    )
    report = run_evaluation(config, log=console.print)
    print_report(report, console)
    if out is not None:
        for path in write_report(report, out):
            console.print(f"wrote {path}")
