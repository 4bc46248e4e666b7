"""Writing a simulated sequence to a folder (what `semloc simulate` produces).

Layout of the folder:

    world.json                  rooms, doors, objects (class, style, pose) of the world
    world.png                   the world from above with the camera path
    global_<kind>.json (+.npz)  global maps (world frame): reconstruction, cad, dynamic
    local.json (+.npz)          the final local map (odometry frame); `seen` drives replay
    keyframes/local_XXXX.json   the local map after each keyframe (with --snapshots)
    ground_truth.json           T_global_local, keyframe poses, correspondences per map kind,
                                dynamic changes (deleted / moved ids)

Every file is written atomically.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from semloc.descriptors import described
from semloc.io.native import save_map
from semloc.io.output import write_atomic
from semloc.sim.scenario import SimulatedSequence


def write_sequence(
    seq: SimulatedSequence, out: Path, snapshots: bool = True, descriptor: str | None = None
) -> list[Path]:
    """Write everything about `seq` under `out` (see the module docstring); the paths written.

    With `descriptor` ("geometric" or "voxnet") every map stores shape descriptors of that kind.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)

    def save(objmap, path: Path) -> Path:

        return save_map(described(objmap, descriptor), path)

    files = []
    write_atomic(out / "world.json", json.dumps(seq.world.summary(), indent=1) + "\n")
    files.append(out / "world.json")
    for kind, gmap in seq.global_maps.items():
        files.append(save(gmap, out / f"global_{kind}.json"))
    files.append(save(seq.local_map, out / "local.json"))
    if snapshots:
        (out / "keyframes").mkdir(exist_ok=True)
        for kf in seq.keyframes:
            path = out / "keyframes" / f"local_{kf.index:04d}.json"
            files.append(save(seq.local_map_at(kf.index), path))
    write_atomic(out / "ground_truth.json", json.dumps(seq.ground_truth(), indent=1) + "\n")
    files.append(out / "ground_truth.json")
    from semloc.pictures.viz import map_figure, plot_world, save_figure

    fig, ax = map_figure(np.array(seq.world.bounds))
    trajectory = np.array([kf.T_world_camera[:2, 3] for kf in seq.keyframes])
    plot_world(ax, seq.world, trajectory=trajectory, title=f"world seed {seq.world.seed}")
    files.append(save_figure(fig, out / "world.png"))
    return files
