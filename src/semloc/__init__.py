"""semloc: object-level relocalization by hierarchical clustering of object association sets.

import semloc
g = semloc.load_map("global.json")
l = semloc.load_map("local.json")
r = semloc.localize(g, l)        # r.status, r.pose (4x4 T_global_local), r.hypotheses
r = semloc.localize(g, l, prior=semloc.Prior(position=[x, y, z], radius=5.0))  # near there
semloc.warmup()                  # compile the inner loops ahead (once after installing)
"""

import sys as _sys

if _sys.argv[:1] == ["-m"]:  # `python -m ...` locating its module: Ctrl-C from the first moment
    import semloc_entry as _entry  # (for `python -m semloc` only, see its docstring)

    _entry.hold_signals_for_module()

from semloc import descriptors  # registers the descriptor kinds (numpy only)
from semloc.alignment import AlignmentConfig, align
from semloc.compiling import warmup  # compiles the inner loops ahead; says once when it does
from semloc.coverage import Coverage
from semloc.io import load_map, save_map
from semloc.localizer import Localizer, LocalizerConfig, localize
from semloc.maps import MapError, ObjectMap, SemanticObject
from semloc.pictures import colors  # label colours of pictures, exports, recordings (no plotting)
from semloc.priors import Prior
from semloc.results import Hypothesis, Look, Result, Step

__version__ = "0.1.0"
__all__ = [
    "AlignmentConfig",
    "Coverage",
    "Hypothesis",
    "Localizer",
    "LocalizerConfig",
    "Look",
    "MapError",
    "ObjectMap",
    "Prior",
    "Result",
    "SemanticObject",
    "Step",
    "__version__",
    "align",
    "colors",
    "descriptors",
    "load_map",
    "localize",
    "save_map",
    "warmup",
]
