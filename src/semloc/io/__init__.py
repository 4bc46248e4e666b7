"""Reading and writing maps: the native semloc format, and importers for public datasets."""

from semloc.io.native import load_map, map_from_dict, map_to_dict, save_map, write_atomic

__all__ = ["load_map", "map_from_dict", "map_to_dict", "save_map", "write_atomic"]
