"""semloc: object-level relocalization by hierarchical clustering of object association sets."""

from semloc.io import load_map, save_map
from semloc.maps import MapError, ObjectMap, SemanticObject

__version__ = "0.1.0"
__all__ = ["MapError", "ObjectMap", "SemanticObject", "load_map", "save_map", "__version__"]
