"""Building a local object map from per-frame 3D instance segments (simulated or real); the
RGB-D keyframes image methods take (`RGBDFrame`, `KeyframeMap`)."""

from semloc.frontend.frames import KeyframeMap, RGBDFrame
from semloc.frontend.fusion import FusionConfig, FusionUpdate, ObjectFusion, Segment
from semloc.frontend.segments import backproject, segments_from_masks
from semloc.pointsets import voxel_downsample

__all__ = [
    "FusionConfig",
    "FusionUpdate",
    "KeyframeMap",
    "ObjectFusion",
    "RGBDFrame",
    "Segment",
    "backproject",
    "segments_from_masks",
    "voxel_downsample",
]
