"""Moved to `semloc.compiling`; this name stays importable (it is that module)."""

import sys

from semloc import compiling

sys.modules[__name__] = compiling
