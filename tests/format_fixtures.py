"""Writers of tiny scenes in the public dataset formats, for the importer tests.

Everything here is generated (boxes with known centres, sizes and yaws); no real data.
Each box's surface is represented by the 26 points of the {-1/2, 0, 1/2}^3 grid without the
centre: symmetric, so the principal axes and the tight box are exactly the box's own.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from semloc.transforms import yaw_rotation as yaw_matrix

GRID = np.array(
    [
        [x, y, z]
        for x in (-0.5, 0, 0.5)
        for y in (-0.5, 0, 0.5)
        for z in (-0.5, 0, 0.5)
        if (x, y, z) != (0, 0, 0)
    ]
)


def box_points(centre, size, yaw: float) -> np.ndarray:
    return (GRID * np.asarray(size)) @ yaw_matrix(yaw).T + np.asarray(centre)


# (objectId, raw label, NYU40 id, centre, size (long side first), yaw)
SCANNET_BOXES = [
    (0, "chair", 5, (1.0, 2.0, 0.45), (0.6, 0.4, 0.9), 0.3),
    (1, "table", 7, (3.0, 1.0, 0.4), (1.6, 0.8, 0.8), -0.7),
    (2, "office chair", 5, (-1.0, 0.5, 0.5), (0.7, 0.5, 1.0), 1.2),
    (3, "wall", 1, (0.0, -2.0, 1.5), (6.0, 0.2, 3.0), 0.0),
    (4, "floor", 2, (0.0, 0.0, -0.05), (6.0, 4.0, 0.1), 0.0),
]


def vertex_array(points: np.ndarray, labels: np.ndarray | None = None) -> np.ndarray:
    fields = [
        ("x", "<f4"),
        ("y", "<f4"),
        ("z", "<f4"),
        ("red", "u1"),
        ("green", "u1"),
        ("blue", "u1"),
        ("alpha", "u1"),
    ]
    if labels is not None:
        fields.append(("label", "<u2"))
    vertices = np.zeros(len(points), dtype=fields)
    for i, c in enumerate("xyz"):
        vertices[c] = points[:, i]
    vertices["red"], vertices["alpha"] = 128, 255
    if labels is not None:
        vertices["label"] = labels
    return vertices


def write_scannet(folder: Path, name: str = "scene0001_00") -> dict:
    """A ScanNet scene: mesh, segs (two segments per box), aggregation, NYU40 label mesh."""
    from semloc.io.ply import write_ply

    folder.mkdir(parents=True, exist_ok=True)
    points, segments, nyu, groups = [], [], [], []
    for object_id, label, nyu_id, centre, size, yaw in SCANNET_BOXES:
        p = box_points(centre, size, yaw)
        seg = np.where(np.arange(len(p)) % 2 == 0, 100 + 2 * object_id, 101 + 2 * object_id)
        points.append(p)
        segments.append(seg)
        nyu.append(np.full(len(p), nyu_id))
        groups.append(
            {
                "id": object_id,
                "objectId": object_id,
                "label": label,
                "segments": sorted(set(seg.tolist())),
            }
        )
    points = np.concatenate(points)
    faces = np.array([[i, i + 1, i + 2] for i in range(0, len(points) - 2, 3)])
    write_ply(folder / f"{name}_vh_clean_2.ply", vertex_array(points), faces)
    write_ply(
        folder / f"{name}_vh_clean_2.labels.ply", vertex_array(points, np.concatenate(nyu)), faces
    )
    segs = {"sceneId": name, "segIndices": np.concatenate(segments).tolist()}
    (folder / f"{name}_vh_clean_2.0.010000.segs.json").write_text(json.dumps(segs))
    aggregation = {"sceneId": name, "appId": "test", "segGroups": groups}
    (folder / f"{name}.aggregation.json").write_text(json.dumps(aggregation))
    return {"name": name, "points": points, "groups": groups}


CUBE_OBJ = """# unit cube, quads with texture/normal indices
v -0.5 -0.5 -0.5
v 0.5 -0.5 -0.5
v 0.5 0.5 -0.5
v -0.5 0.5 -0.5
v -0.5 -0.5 0.5
v 0.5 -0.5 0.5
v 0.5 0.5 0.5
v -0.5 0.5 0.5
vt 0 0
vn 0 0 1
f 1/1/1 2/1/1 3/1/1 4/1/1
f 5/1/1 6/1/1 7/1/1 8/1/1
f 1//1 2//1 6//1 5//1
f 2 3 7 6
f 3 4 8 7
f -8 -4 -1 -5
"""


def quaternion_wxyz(axis, angle: float) -> list[float]:
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return [float(np.cos(angle / 2)), *(np.sin(angle / 2) * axis).tolist()]


# (catid, id_cad, translation (world), yaw (about world y), scale)
SCAN2CAD_MODELS = [
    ("03001627", "chaircube", (1.0, 0.45, -2.0), 0.4, (0.5, 0.9, 0.6)),
    ("03001627", "chaircube", (2.5, 0.45, -2.0), -0.3, (0.5, 0.9, 0.6)),
    ("04379243", "tablecube", (1.5, 0.4, -0.5), 0.0, (1.2, 0.8, 0.7)),
]
SCAN2CAD_SCAN_TRS = {  # scan (z up) -> world (y up): rotation about x by -90 degrees
    "translation": [0.3, -0.2, 0.1],
    "rotation": quaternion_wxyz((1, 0, 0), -np.pi / 2),
    "scale": [1.0, 1.0, 1.0],
}


def write_scan2cad(folder: Path, name: str = "scene0002_00") -> Path:
    """A Scan2CAD annotation, a ShapeNet folder with a cube model, and a NYU40 label mesh."""
    from scipy.spatial.transform import Rotation

    from semloc.io.ply import write_ply

    scene = folder / name
    scene.mkdir(parents=True, exist_ok=True)
    models = []
    for catid, id_cad, t, yaw, s in SCAN2CAD_MODELS:
        model_dir = folder / "shapenet" / catid / id_cad
        model_dir.mkdir(parents=True, exist_ok=True)
        (model_dir / "model_normalized.obj").write_text(CUBE_OBJ)
        models.append(
            {
                "catid_cad": catid,
                "id_cad": id_cad,
                "bbox": [0.5, 0.5, 0.5],
                "center": [0, 0, 0],
                "sym": "__SYM_NONE",
                "trs": {
                    "translation": list(t),
                    "rotation": quaternion_wxyz((0, 1, 0), yaw),
                    "scale": list(s),
                },
            }
        )
    annotation = [
        {
            "id_scan": name,
            "trs": SCAN2CAD_SCAN_TRS,
            "aligned_models": models,
            "n_aligned_models": len(models),
        }
    ]
    path = scene / "scan2cad_annotation.json"
    path.write_text(json.dumps(annotation))
    # the scan: points of each model's box (class of the model) + a door + a wall
    q = SCAN2CAD_SCAN_TRS["rotation"]
    scan_from_world = Rotation.from_quat([q[1], q[2], q[3], q[0]]).inv()
    t_scan = np.array(SCAN2CAD_SCAN_TRS["translation"])
    points, labels = [], []
    for (_, _, t, yaw, s), nyu in zip(SCAN2CAD_MODELS, (5, 5, 7), strict=True):
        world = Rotation.from_rotvec([0, yaw, 0]).apply(GRID * np.array(s) * 0.95) + t
        points.append(scan_from_world.apply(world - t_scan))
        labels.append(np.full(len(GRID), nyu))
    gx, gz = np.meshgrid(np.linspace(3.5, 4.5, 21), np.linspace(0.0, 2.0, 41))
    door = np.column_stack([gx.ravel(), np.zeros(gx.size), gz.ravel()])  # a dense door panel
    wx, wz = np.meshgrid(np.linspace(-3.0, 3.0, 121), np.linspace(0.0, 3.0, 61))
    wall = np.column_stack([wx.ravel(), np.full(wx.size, 3.0), wz.ravel()])
    points += [door, wall]
    labels += [np.full(len(door), 8), np.full(len(wall), 1)]
    write_ply(
        scene / f"{name}_vh_clean_2.labels.ply",
        vertex_array(np.concatenate(points), np.concatenate(labels)),
    )
    return path


# (id, class_name, abb centre (box frame), sizes, yaw about z, translation)
REPLICA_OBJECTS = [
    (3, "chair", (0.5, 0.2, 0.4), (0.5, 0.6, 0.9), 0.5, (0.0, 0.0, 0.0)),
    (7, "table", (1.0, -1.0, 0.35), (1.2, 0.8, 0.7), -1.0, (0.2, 0.1, 0.0)),
    (8, "wall", (0.0, 3.0, 1.4), (6.0, 0.1, 2.8), 0.0, (0.0, 0.0, 0.0)),
    (9, "undefined", (2.0, 2.0, 0.1), (0.1, 0.1, 0.1), 0.0, (0.0, 0.0, 0.0)),
]


def write_replica(folder: Path, gravity=(0.0, 0.0, -1.0)) -> Path:
    """An `info_semantic.json` with boxes rotated about z (quaternions stored x, y, z, w)."""
    folder.mkdir(parents=True, exist_ok=True)
    objects = []
    for object_id, name, centre, sizes, yaw, translation in REPLICA_OBJECTS:
        xyzw = [0.0, 0.0, float(np.sin(yaw / 2)), float(np.cos(yaw / 2))]
        objects.append(
            {
                "id": object_id,
                "class_id": object_id,
                "class_name": name,
                "oriented_bbox": {
                    "abb": {"center": list(centre), "sizes": list(sizes)},
                    "orientation": {"rotation": xyzw, "translation": list(translation)},
                },
            }
        )
    document = {"classes": [], "id_to_label": [], "gravity_dir": list(gravity), "objects": objects}
    path = folder / "info_semantic.json"
    path.write_text(json.dumps(document))
    return path


# (objectId, NYU40, RIO27, centre, size) -- axis-aligned boxes
RSCAN_OBJECTS = [
    (0, 0, 0, (0.0, 0.0, 0.0), (3.0, 3.0, 2.0)),
    (4, 5, 5, (1.0, 0.5, 0.45), (0.5, 0.4, 0.9)),
    (7, 7, 7, (2.0, -1.0, 0.4), (1.4, 0.9, 0.8)),
    (9, 3, 3, (-1.0, 1.0, 0.9), (0.8, 0.5, 1.8)),
    (12, 1, 1, (0.0, 2.5, 1.5), (5.0, 0.1, 3.0)),
]


def write_rscan(folder: Path, drop_field: str | None = None) -> Path:
    """A structured `data.npy` like SGAligner's subscans."""
    folder.mkdir(parents=True, exist_ok=True)
    fields = [
        ("x", "<f4"),
        ("y", "<f4"),
        ("z", "<f4"),
        ("red", "u1"),
        ("green", "u1"),
        ("blue", "u1"),
        ("objectId", "<i2"),
        ("globalId", "<i2"),
        ("NYU40", "u1"),
        ("Eigen13", "u1"),
        ("RIO27", "u1"),
    ]
    fields = [f for f in fields if f[0] != drop_field]
    chunks = []
    for object_id, nyu, rio, centre, size in RSCAN_OBJECTS:
        p = box_points(centre, size, 0.0)
        chunk = np.zeros(len(p), dtype=fields)
        for i, c in enumerate("xyz"):
            chunk[c] = p[:, i]
        for name, value in (("objectId", object_id), ("NYU40", nyu), ("RIO27", rio)):
            if name in chunk.dtype.names:
                chunk[name] = value
        chunks.append(chunk)
    data = np.concatenate(chunks)
    np.random.default_rng(0).shuffle(data)
    path = folder / "data.npy"
    np.save(path, data, allow_pickle=False)
    return path
