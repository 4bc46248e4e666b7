"""FCGF-style, dense + RANSAC: the paper's learned geometric-feature baseline (Choy, Park and
Koltun, "Fully Convolutional Geometric Features", ICCV 2019) in the FPFH row's pipeline.

The same registration as `semloc.baselines.fpfh` (sub-maps on a 0.3 m grid of 1.5 m radius, a
shape vocabulary trained on the global map's features to retrieve sub-maps, RANSAC on mutual
feature matches, object association after the RANSAC pose and the shared pose recovery,
hypotheses ranked by point fitness), with FPFH replaced by learned dense features: the
FCGF-style network of `semloc.descriptors.fcgf` (dense 3D convolutions kept at occupied 0.1 m
cells, trained with the hardest-contrastive loss on the simulator's training worlds; shipped
weights, numpy inference), one 32-dimensional feature per 0.1 m cell.

Not FCGF itself: FCGF is a sparse residual U-Net (MinkowskiEngine, CUDA) trained on 3DMatch;
this is a small dense network of four dilated layers trained on simulated object maps, so that
it trains on a CPU in minutes (`semloc train-descriptor --kind fcgf-dense`).
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from semloc.baselines.fpfh import FpfhConfig, FpfhRansacBaseline
from semloc.descriptors import fcgf


class FcgfConfig(FpfhConfig):
    voxel: float = Field(fcgf.VOXEL, gt=0, description="Voxel size (m) before features.")

    def features(self, pcd) -> np.ndarray:
        """FCGF-style features (N, 32) of the downsampled cloud's points."""
        return fcgf.point_features(np.asarray(pcd.points)).astype(float)


class FcgfDenseBaseline(FpfhRansacBaseline):
    """FCGF-style dense learned features, vocabulary retrieval, RANSAC, shared pose."""

    name = "fcgf-dense"
    config_class = FcgfConfig
    config: FcgfConfig
