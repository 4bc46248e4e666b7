"""Moved to `semloc.pictures.viz3d`; this name stays importable (it is that module)."""

import sys

from semloc.pictures import viz3d

sys.modules[__name__] = viz3d
