"""Local observations cut from a map: what a robot at `center` would see within `radius`.

`crop_map` keeps the objects whose centre is within `radius` of the viewpoint, keeps only the
points on the side of each object that faces the viewpoint (half-space test about the object
centre; descriptors of objects with points are dropped, as they describe the whole object),
renames the objects (`l0`, `l1`, ... in order of distance, which is also their `seen`
order) and expresses everything in a new frame: `p_local = inv(T_global_local) @ p_global`.
With a random transform the local frame sits at the viewpoint with a random heading, as a
robot's own frame would.  The returned `CropTruth` holds `T_global_local` and the id pairs;
`crop_truth_to_dict` is the JSON written beside the local map (`LOCAL.gt.json`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from semloc.io.geometry import quaternion_matrix, up_basis, upright_box
from semloc.maps import MapError, ObjectMap, SemanticObject
from semloc.transforms import as_pose


@dataclass(frozen=True)
class CropTruth:
    """Ground truth of a crop: the pose of the local frame and the (global, local) id pairs."""

    T_global_local: np.ndarray
    pairs: list[tuple[str, str]]
    center: np.ndarray
    radius: float


def crop_map(
    objmap: ObjectMap,
    center: Any,
    radius: float,
    transform: str | np.ndarray | None = "random",
    seed: int | None = 0,
    min_points: int = 3,
    recentre: bool = False,
) -> tuple[ObjectMap, np.ndarray]:
    """The local map seen from `center` and its pose `T_global_local` (see `crop_with_truth`)."""
    local, truth = crop_with_truth(objmap, center, radius, transform, seed, min_points, recentre)
    return local, truth.T_global_local


def crop_with_truth(
    objmap: ObjectMap,
    center: Any,
    radius: float,
    transform: str | np.ndarray | None = "random",
    seed: int | None = 0,
    min_points: int = 3,
    recentre: bool = False,
) -> tuple[ObjectMap, CropTruth]:
    """Crop `objmap` around `center` (objects whose centre is within `radius`).

    `transform`: "random" (the local frame sits at `center` with a random heading: a yaw
    about `up` when the map has one, drawn with `seed`), a 4x4 `T_global_local`, or None
    (identity: the local frame is the global one).  Objects with points keep those facing
    the viewpoint; one left with fewer than `min_points` of them keeps its `min_points`
    points nearest to the viewpoint.  With `recentre`, an object's position and box are
    re-fitted to its visible points (as a detector seeing one side would report them).
    """
    center = np.asarray(center, dtype=float)
    if center.shape != (3,) or not np.all(np.isfinite(center)):
        raise MapError(f"center must be 3 finite numbers, got {center.tolist()}")
    if not np.isfinite(radius) or radius <= 0:
        raise MapError(f"radius must be a positive number, got {radius}")
    T = pose_for(transform, objmap.up, seed, origin=center)
    distances = np.linalg.norm(objmap.positions - center, axis=1) if len(objmap) else []
    order = [i for i in np.argsort(distances, kind="stable") if distances[i] <= radius]
    local_from_global = np.linalg.inv(T)
    objects, pairs = [], []
    for rank, index in enumerate(order):
        obj = objmap[int(index)]
        points = visible_points(obj, center, min_points)
        seen_obj = obj.replace(id=f"l{rank}", seen=rank, points=points)
        if points is not None:  # a descriptor of the whole object would not fit the cut points
            seen_obj = seen_obj.replace(descriptor=None)
        if recentre and points is not None and len(points):
            position, size, rotation = upright_box(points, objmap.up)
            seen_obj = seen_obj.replace(position=position, size=size, rotation=rotation)
        objects.append(seen_obj.transformed(local_from_global))
        pairs.append((obj.id, f"l{rank}"))
    up = None if objmap.up is None else local_from_global[:3, :3] @ objmap.up
    name = f"{objmap.name}_crop" if objmap.name else "crop"
    local = ObjectMap(objects, up=up, name=name)
    return local, CropTruth(T, pairs, center, float(radius))


def visible_points(
    obj: SemanticObject, viewpoint: np.ndarray, min_points: int = 3
) -> np.ndarray | None:
    """The points of `obj` on its side facing `viewpoint` (None when it has no points)."""
    if obj.points is None or len(obj.points) == 0:
        return obj.points
    direction = viewpoint - obj.position
    norm = np.linalg.norm(direction)
    if norm < 1e-9:
        return obj.points
    facing = (obj.points - obj.position) @ (direction / norm) >= 0
    if facing.sum() >= min_points:
        return obj.points[facing]
    nearest = np.argsort(np.linalg.norm(obj.points - viewpoint, axis=1))[:min_points]
    return obj.points[np.sort(nearest)]


def pose_for(
    transform: str | np.ndarray | None,
    up: np.ndarray | None,
    seed: int | None,
    origin: np.ndarray | None = None,
) -> np.ndarray:
    """A 4x4 pose from the `transform` argument of `crop_map` (random: see `random_pose`)."""
    if transform is None:
        return np.eye(4)
    if isinstance(transform, str):
        if transform != "random":
            raise MapError(f"transform must be 'random', a 4x4 matrix or None, got {transform!r}")
        return random_pose(np.random.default_rng(seed), up, origin)
    try:
        return as_pose(transform, "transform")
    except ValueError as exc:
        raise MapError(str(exc)) from None


def random_pose(
    rng: np.random.Generator, up: np.ndarray | None, origin: np.ndarray | None = None
) -> np.ndarray:
    """A random frame at `origin` (the viewpoint: so the pose's translation error is the
    robot's position error): random yaw about `up`, or any rotation when `up` is None."""
    T = np.eye(4)
    if up is None:
        T[:3, :3] = quaternion_matrix(*rng.normal(size=4))
    else:
        basis = up_basis(up)
        angle = rng.uniform(-np.pi, np.pi)
        c, s = np.cos(angle), np.sin(angle)
        yaw = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        T[:3, :3] = basis @ yaw @ basis.T
    T[:3, 3] = np.zeros(3) if origin is None else origin
    return T


def crop_truth_to_dict(truth: CropTruth, global_name: str = "") -> dict[str, Any]:
    """The ground-truth document written beside a crop (`LOCAL.gt.json`)."""
    return {
        "format": "semloc-crop-truth",
        "version": 1,
        "global_map": global_name,
        "center": np.round(truth.center, 6).tolist(),
        "radius": truth.radius,
        "T_global_local": np.round(truth.T_global_local, 9).tolist(),
        "pairs": [{"global": g, "local": loc} for g, loc in truth.pairs],
    }
