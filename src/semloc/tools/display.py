"""Moved to `semloc.pictures.display`; this name stays importable (it is that module)."""

import sys

from semloc.pictures import display

sys.modules[__name__] = display
