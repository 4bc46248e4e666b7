"""`semloc train-descriptor` (VoxNet, needs torch) and `semloc descriptors-eval`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from semloc.association import DESCRIBERS
from semloc.cli.app import MAX_SEED, app, choices, console
from semloc.cli.extras import need
from semloc.cli.files import check_separate
from semloc.descriptors.voxnet import WEIGHTS_FILE, load_weights
from semloc.eval.descriptors.evaluate import EvalConfig, print_report, run_evaluation, write_report
from semloc.eval.descriptors.train import TrainConfig, save_weights, train

DescriptorChoice = choices("DescriptorChoice", [*DESCRIBERS, "both"])


@app.command("train-descriptor")
def train_descriptor(
    out: Annotated[Path, typer.Option(help="Weights file to write (.npz).")] = Path(
        "voxnet_weights.npz"
    ),
    seed: Annotated[
        int,
        typer.Option(min=0, max=MAX_SEED, help="Seed of the data, the initialisation and batches."),
    ] = 0,
    epochs: Annotated[int, typer.Option(min=1, max=1000, help="Training epochs.")] = 6,
    views: Annotated[
        int, typer.Option(min=6, max=10_000, help="Partial views per training instance.")
    ] = 48,
    full_views: Annotated[
        int, typer.Option(min=2, max=10_000, help="Whole-surface (CAD-style) views per instance.")
    ] = 12,
    batches: Annotated[int, typer.Option(min=1, max=100_000, help="Batches per epoch.")] = 30,
    fixture: Annotated[
        Path | None,
        typer.Option(help="Also write test grids + torch embeddings (.npz) for the numpy test."),
    ] = None,
) -> None:
    """Train the VoxNet descriptor (triplet loss on simulated objects); needs torch.

    The defaults reproduce the shipped weights (src/semloc/descriptors/voxnet_weights.npz).
    """
    check_separate({"--out": out, "--fixture": fixture}, {})
    need("train-descriptor", "train", "sim")
    config = TrainConfig(
        seed=seed, epochs=epochs, views=views, full_views=full_views, batches_per_epoch=batches
    )
    weights, summary = train(config, log=console.print)
    save_weights(weights, out)
    size = out.stat().st_size / 1e6
    console.print(f"wrote {out} ({size:.2f} MB) in {summary['seconds']:.0f} s")
    if fixture is not None:
        save_weights(summary["fixture"], fixture)
        console.print(f"wrote {fixture}")
    if WEIGHTS_FILE.exists() and out.resolve() != WEIGHTS_FILE.resolve():
        shipped = load_weights()
        diff = max(float(np.abs(shipped[k] - weights[k]).max()) for k in weights)
        same = "identical to" if diff == 0 else f"max |diff| {diff:.2e} from"
        console.print(f"{same} the shipped weights")


@app.command("descriptors-eval")
def descriptors_eval(
    kind: Annotated[DescriptorChoice, typer.Option(help="Descriptor kind(s) to evaluate.")] = (
        DescriptorChoice["both"]
    ),
    out: Annotated[
        Path | None, typer.Option(help="Folder for descriptors_eval.json and figures.")
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
