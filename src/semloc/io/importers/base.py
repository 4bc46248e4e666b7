"""What an importer is: a named reader of one dataset's files into semloc maps.

An importer module (one per dataset, in this package) defines `IMPORTER = Importer(...)`; the
registry in `__init__.py` lists the modules.  `semloc convert`'s choices and help come from it.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field

from semloc.maps import MapError, ObjectMap

Maps = tuple[ObjectMap, ObjectMap | None]  # the map, and a second one (Scan2CAD: scan-derived)

COMMON_OPTIONS = ("labels", "include_structure", "voxel", "seed")
"""Options every importer receives (it may ignore seed or voxel when it has no use for them)."""


@dataclass(frozen=True)
class Importer:
    """One dataset format: `convert(source, **options) -> (map, second map or None)`.

    `options` names the options beyond `COMMON_OPTIONS` that it accepts; `source_help` says what
    INPUT is; `labels_help` lists its label vocabularies (None: it has one, `--labels` refused).
    """

    name: str
    convert: Callable[..., Maps]
    source_help: str
    labels_help: str | None = None
    options: frozenset[str] = field(default_factory=frozenset)

    def __call__(self, source: str | os.PathLike[str], **options) -> Maps:
        """The maps of `source`; a `MapError` that names no file gets the source's name."""
        try:
            return self.convert(source, **options)
        except MapError as exc:
            if os.sep in str(exc).split(":")[0] or str(source) in str(exc):
                raise
            raise MapError(f"{source}: {exc}") from None
