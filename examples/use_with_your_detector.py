"""semloc with your own detector: depth + instance masks + camera poses -> objects -> pose.

Per frame your pipeline has a depth image, instance masks with labels (any segmenter) and the
camera pose from odometry (`T_odom_camera`).  `segments_from_masks` turns them into 3D
segments, `ObjectFusion` fuses the segments of all frames into local objects with stable ids,
and `Localizer.update` takes the objects that are new or changed after each frame.  The
answer is `T_global_odom`: where your odometry frame lies in the prior map.

Here the frames are made up (`semloc.tools.standins.your_frames`) by projecting points on the
surfaces of the example room's objects into a camera that turns around in the room, so the
example runs anywhere with the core install:

    python examples/use_with_your_detector.py

The README's block imports the same stand-ins (`K`, `MAP_FILE`, `your_frames`).
"""

from __future__ import annotations

import semloc
from semloc.frontend import ObjectFusion, segments_from_masks
from semloc.tools.standins import MAP_FILE, T_GLOBAL_ODOM, K, your_frames
from semloc.transforms import pose_error


def main() -> None:
    global_map = semloc.load_map(MAP_FILE)
    fusion = ObjectFusion()
    localizer = semloc.Localizer(global_map, local_up=[0, 0, 1])
    result = None
    for frame, (depth, masks, labels, T_odom_camera) in enumerate(your_frames()):
        segments = segments_from_masks(depth, masks, labels, K)
        update = fusion.integrate(segments, T_odom_camera, frame="camera")
        if update.changed:  # objects that are new or moved
            result = localizer.update(fusion.objects(update.changed))
            print(f"frame {frame:2d}: {len(localizer.local_map)} local objects, {result.status}")
    assert result is not None and result.pose is not None
    rotation, translation = pose_error(result.pose, T_GLOBAL_ODOM)
    print(f"T_global_odom found: {result.status}, error {rotation:.2f} deg / {translation:.3f} m")


if __name__ == "__main__":
    main()
