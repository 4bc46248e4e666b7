"""The day / night pair at a glance: one query keyframe by day and at night, SIFT keypoints drawn.

Renders keyframe `--keyframe` of the benchmark's first simulated walk (seed `--seed`, small
world) under daylight and under the night model (`semloc.sim.illumination.NIGHT`) exactly as
`semloc bench` hands them to the image methods (`semloc.eval.images.query_frame`), prints the
mean brightness and the number of SIFT keypoints of each (the SIFT baseline's detector
settings, before the depth check), and writes both side by side with the keypoints drawn.

    PYTHONPATH=src python benchmarks/day_night.py [--seed 0] [--keyframe 10] \\
        [--out docs/img/day_night.png]
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np

from semloc.baselines.sift import SiftConfig
from semloc.eval.images import query_frame
from semloc.eval.protocol import BenchConfig, simulate


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=0, help="the benchmark's seed")
    parser.add_argument("--keyframe", type=int, default=10, help="keyframe of the first walk")
    parser.add_argument("--out", default="day_night.png", help="the picture (PNG)")
    args = parser.parse_args(argv)
    config = BenchConfig(seed=args.seed, keyframes=max(80, args.keyframe + 1),
                         map_kinds=["reconstruction"])  # fmt: skip
    seq = simulate(config, 0)
    keyframe = seq.keyframes[args.keyframe]
    cfg = SiftConfig()
    sift = cv2.SIFT_create(nfeatures=cfg.features, contrastThreshold=cfg.contrast_threshold)
    panels = []
    print("| light | mean brightness (0-255) | SIFT keypoints |\n|---|---|---|")
    for light in ("day", "night"):
        frame = query_frame(seq.world, keyframe, light)
        keypoints = sift.detect(frame.gray, None)
        print(f"| {light} | {frame.rgb.mean():.1f} | {len(keypoints)} |")
        image = np.ascontiguousarray(frame.rgb[..., ::-1])
        panels.append(cv2.drawKeypoints(image, keypoints, None, color=(0, 255, 255)))
    gap = np.full((panels[0].shape[0], 6, 3), 255, np.uint8)
    cv2.imwrite(args.out, np.hstack([panels[0], gap, panels[1]]), [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
