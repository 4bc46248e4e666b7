"""A hand-made shape descriptor (no learning) that tolerates partial views.

Computed in the canonical frame of `frame.canonical` (gravity up, yaw and translation removed,
points thinned to 3 cm cells), so it is invariant to rotation about gravity and to translation
and changes little when points are dropped.  The vector (length `LENGTH`) concatenates:

- size: robust height (z at 98 %), horizontal extents along the principal axes (2-98 %
  spread) and horizontal standard deviations, in metres;
- height profile: share of the points in 12 height bins of 0.2 m (0 .. 2.4 m);
- radial profile: share of the points in 8 bins of horizontal distance from the vertical
  axis through the centroid (0.15 m wide);
- height x radius: a coarse 4 x 3 joint histogram (0.6 m x 0.4 m cells);
- shape ratios: linearity, planarity and scattering of the 3D covariance eigenvalues.

Histograms are shares (they sum to one), so they hardly change with density; sizes are metric
and dominate the distance between classes, profiles separate styles of a class.
"""

from __future__ import annotations

import numpy as np

from semloc.descriptors.frame import canonical

HEIGHT_BINS = np.linspace(0.0, 2.4, 13)
RADIAL_BINS = np.linspace(0.0, 1.2, 9)
JOINT_Z = np.array([0.0, 0.6, 1.2, 1.8, np.inf])
JOINT_R = np.array([0.0, 0.4, 0.8, np.inf])
LENGTH = 5 + 12 + 8 + 12 + 3
WEIGHTS = np.concatenate(
    [np.full(5, 1.0), np.full(12, 0.7), np.full(8, 0.7), np.full(12, 0.5), np.full(3, 0.3)]
)


def _share(values: np.ndarray, edges: np.ndarray) -> np.ndarray:
    counts, _ = np.histogram(np.clip(values, edges[0], edges[-1] - 1e-9), bins=edges)
    return counts / max(len(values), 1)


def geometric_descriptor(points: np.ndarray) -> np.ndarray:
    """The geometric descriptor (float64, length `LENGTH`) of one object's points (N, 3)."""
    local = canonical(points)
    x, y, z = local[:, 0], local[:, 1], local[:, 2]
    radius = np.hypot(x, y)
    size = np.array(
        [
            np.percentile(z, 98),
            np.percentile(x, 98) - np.percentile(x, 2),
            np.percentile(y, 98) - np.percentile(y, 2),
            x.std(),
            y.std(),
        ]
    )
    joint, _, _ = np.histogram2d(np.clip(z, 0, 10), np.clip(radius, 0, 10), bins=(JOINT_Z, JOINT_R))
    eig = np.sort(np.linalg.eigvalsh(np.cov(local.T)))[::-1]
    eig = np.maximum(eig, 1e-12)
    ratios = np.array([(eig[0] - eig[1]) / eig[0], (eig[1] - eig[2]) / eig[0], eig[2] / eig[0]])
    vector = np.concatenate(
        [
            size,
            _share(z, HEIGHT_BINS),
            _share(radius, RADIAL_BINS),
            joint.ravel() / len(local),
            ratios,
        ]
    )
    return vector * WEIGHTS
