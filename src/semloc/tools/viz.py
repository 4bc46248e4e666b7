"""Moved to `semloc.pictures.viz`; this name stays importable (it is that module)."""

import sys

from semloc.pictures import viz

sys.modules[__name__] = viz
