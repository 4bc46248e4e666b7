"""Moved to `semloc.pictures.colors`; this name stays importable (it is that module)."""

import sys

from semloc.pictures import colors

sys.modules[__name__] = colors
