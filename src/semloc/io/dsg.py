"""Spark-DSG (Hydra) scene graphs: their object layer read as a semloc map, and a map written
back as a scene graph.  Needs the `semloc[dsg]` extra (`spark-dsg`), imported on first use.

Reading (`load_dsg`): every node of the OBJECTS layer (layer 2, partition 0) is an object: id
the node symbol (`O(7)`; the semloc id for graphs semloc wrote, kept in the node's metadata),
label the name of its `semantic_label` in the graph's label space for that layer (or in a
label map the caller gives; `class_<n>` where neither has it), position the node's position, the bounding box when it is valid
(centre, dimensions, rotation; the semloc box is about the centre, so its centre becomes the
position when the two differ), points the mesh vertices the node connects to (`mesh_connections`),
`up` +z (Hydra's world frame).  Each object keeps `{"dsg": {"symbol", "semantic_label"}}` so a
map written back keeps symbols and label numbers; objects flagged missing by `semloc update-map`
carry `{"semloc": {"missing": true}}` in the node metadata.  An object under a room keeps it as
`extra["room"]` (the room node's symbol, `R(3)`, or the semloc room id kept in its metadata):
the first node of the ROOMS layer (layer 4) up its parent chain, as Hydra links objects to
places and places to rooms (or objects to rooms directly); one walk per node, remembered, so
the rooms of a large graph cost one visit per node.

Writing (`dsg_bytes`): one OBJECTS node per object (symbol kept, or the next free `O(n)`), the
label space of the map's labels (numbers kept where the map came from a graph), OBB boxes, and
a mesh holding every object's points as vertices (no faces), connected to their nodes, and a
ROOMS node per `extra["room"]` (its symbol where the room is one no object takes, else the next
free `R(n)` with the id in its metadata) at the mean position of its objects, their parent.
"""

from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from semloc.io import read_json, read_regular
from semloc.maps import MapError, ObjectMap, SemanticObject
from semloc.pointsets import voxel_downsample

OBJECTS_LAYER = 2
ROOMS_LAYER = 4
SYMBOL = re.compile(r"^([A-Za-z])\((\d+)\)$")
UP = np.array([0.0, 0.0, 1.0])


def _spark() -> Any:
    import spark_dsg

    return spark_dsg


def load_dsg(
    path: str | os.PathLike[str], voxel: float = 0.0, names: Mapping[int, str] | None = None
) -> ObjectMap:
    """The objects of a Spark-DSG graph (.json or binary) as a map (see the module docstring);
    points voxel-downsampled with edge `voxel` (0: all); `names` of label numbers win over the
    graph's label space.  MapError naming the file if it is not a readable scene graph or has
    no objects."""
    path = Path(path)
    graph = _load(path)
    layer = graph.get_layer(OBJECTS_LAYER) if graph.has_layer(OBJECTS_LAYER) else None
    nodes = [] if layer is None else list(layer.nodes)
    if not nodes:
        raise MapError(f"{path}: the scene graph has no objects (layer {OBJECTS_LAYER}, OBJECTS)")
    names = {**_label_names(graph), **(names or {})}
    vertices = _vertices(graph)
    rooms = _rooms(graph, nodes)
    objects = [
        _object(path, node, names, vertices, voxel, rooms.get(node.id.value)) for node in nodes
    ]
    return ObjectMap(objects, up=UP, name=path.name.split(".")[0])


def _load(path: Path) -> Any:
    if path.suffix.lower() == ".json":  # checked by the guarded JSON reader first
        document = read_json(path)
        if not isinstance(document, dict) or "nodes" not in document:
            raise MapError(f"{path}: not a Spark-DSG scene graph (no 'nodes')")
    else:
        read_regular(path)
    try:
        return _spark().DynamicSceneGraph.load(str(path))
    except Exception as exc:  # the bindings raise RuntimeError, ValueError, ...
        why = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise MapError(f"{path}: not a readable Spark-DSG scene graph ({why})") from None


def _label_names(graph: Any) -> dict[int, str]:
    try:
        return dict(graph.get_labelspace(OBJECTS_LAYER, 0).labels_to_names)
    except Exception:  # no label space for the layer
        return {}


def _rooms(graph: Any, nodes: list[Any]) -> dict[int, str]:
    """The room id of each node of `nodes` under a room (by node id): the first ROOMS node up
    its parents (a parent in ROOMS first, then the others' rooms, lowest id first)."""
    try:
        key = graph.get_layer_key("ROOMS")
    except Exception:  # a graph without layer names
        key = None
    rooms_layer = ROOMS_LAYER if key is None else int(key.layer)
    found: dict[int, str | None] = {}  # node id -> its room id, None for none (or being walked)

    def room_of(node_id: int) -> str | None:
        if node_id in found:
            return found[node_id]
        found[node_id] = None  # a cycle ends here
        node = graph.get_node(node_id)
        if node.layer.layer == rooms_layer:
            meta = node.attributes.metadata.get() or {}
            own = meta.get("semloc") if isinstance(meta.get("semloc"), dict) else {}
            kept = own.get("id")
            found[node_id] = kept if isinstance(kept, str) and kept else str(node.id)
        elif node.layer.layer < rooms_layer:
            parents = sorted(node.parents())
            direct = [p for p in parents if graph.get_node(p).layer.layer == rooms_layer]
            for parent in direct or parents:
                room = room_of(parent)
                if room is not None:
                    found[node_id] = room
                    break
        return found[node_id]

    rooms = {}
    for node in nodes:
        room = room_of(node.id.value)
        if room is not None:
            rooms[node.id.value] = room
    return rooms


def _vertices(graph: Any) -> np.ndarray | None:
    if not graph.has_mesh() or graph.mesh.num_vertices() == 0:
        return None
    return np.asarray(graph.mesh.get_vertices(), dtype=float)[:3].T


def _object(path: Path, node: Any, names: dict[int, str], vertices: np.ndarray | None,
            voxel: float, room: str | None = None) -> SemanticObject:  # fmt: skip
    attrs = node.attributes
    symbol = str(node.id)
    meta = attrs.metadata.get() or {}
    own = meta.get("semloc", {}) if isinstance(meta.get("semloc"), dict) else {}
    number = int(attrs.semantic_label)
    label = names.get(number) or f"class_{number}"
    position = np.asarray(attrs.position, dtype=float)
    size = rotation = None
    box = attrs.bounding_box
    if box.is_valid():
        size = np.asarray(box.dimensions, dtype=float)
        rotation = np.asarray(box.world_R_center, dtype=float)
        position = np.asarray(box.world_P_center, dtype=float)
    points = None
    connections = np.asarray(list(attrs.mesh_connections), dtype=np.int64)
    if vertices is not None and len(connections):
        inside = connections[(connections >= 0) & (connections < len(vertices))]
        points = vertices[inside] if voxel <= 0 else voxel_downsample(vertices[inside], voxel)
    extra: dict[str, Any] = {"dsg": {"symbol": symbol, "semantic_label": number}}
    if own.get("missing") is True:
        extra["missing"] = True
    if room is not None:
        extra["room"] = room
    object_id = own.get("id") if isinstance(own.get("id"), str) and own.get("id") else symbol
    try:
        return SemanticObject(object_id, label, position, size, rotation, points, extra=extra)
    except MapError as exc:
        raise MapError(f"{path}: node {symbol}: {exc}") from None


def dsg_bytes(objmap: ObjectMap, path: str | os.PathLike[str]) -> bytes:
    """The scene graph of `objmap` encoded as Spark-DSG writes it for `path`'s suffix (.json:
    JSON, else its binary format); nothing is written to `path`."""
    spark = _spark()
    graph = spark.DynamicSceneGraph()
    numbers = _label_numbers(objmap)
    symbols = _symbols(objmap)
    mesh, offset = spark.Mesh(), 0
    all_points = [o.points for o in objmap if o.points is not None and len(o.points)]
    mesh.resize_vertices(sum(len(p) for p in all_points))
    for obj in objmap:
        letter, index = symbols[obj.id]
        attrs = _attributes(spark, obj, numbers[obj.label], f"{letter}({index})")
        if obj.points is not None and len(obj.points):
            for i, p in enumerate(np.asarray(obj.points, dtype=np.float32)):
                mesh.set_pos(offset + i, p)
            attrs.mesh_connections = list(range(offset, offset + len(obj.points)))
            offset += len(obj.points)
        graph.add_node(OBJECTS_LAYER, spark.NodeSymbol(letter, index), attrs)
    graph.set_labelspace(spark.Labelspace({n: label for label, n in numbers.items()}),
                         OBJECTS_LAYER, 0)  # fmt: skip
    _add_rooms(spark, graph, objmap, symbols)
    if offset:
        graph.mesh = mesh
    suffix = Path(path).suffix or ".json"
    with tempfile.TemporaryDirectory() as folder:
        target = Path(folder) / f"graph{suffix}"
        graph.save(str(target), True)
        return target.read_bytes()


def _add_rooms(spark: Any, graph: Any, objmap: ObjectMap,
               symbols: dict[str, tuple[str, int]]) -> None:  # fmt: skip
    """A ROOMS node per room id of the objects' `extra["room"]`, at their mean position, the
    parent of each: the room's symbol where it is one the objects leave free, else the next
    free `R(n)` keeping the id in its metadata."""
    members: dict[str, list[SemanticObject]] = {}
    for obj in objmap:
        room = obj.extra.get("room")
        if isinstance(room, str) and room:
            members.setdefault(room, []).append(obj)
    taken = set(symbols.values())
    chosen: dict[str, tuple[str, int]] = {}
    for room in members:
        match = SYMBOL.match(room)
        if match is not None and (match[1], int(match[2])) not in taken:
            chosen[room] = (match[1], int(match[2]))
            taken.add(chosen[room])
    free = (n for n in range(10**9) if ("R", n) not in taken)
    for room in members:
        if room not in chosen:
            chosen[room] = ("R", next(free))
    for room, objects in members.items():
        attrs = spark.RoomNodeAttributes()
        attrs.position = np.mean([np.asarray(o.position, dtype=float) for o in objects], axis=0)
        letter, index = chosen[room]
        if room != f"{letter}({index})":  # the symbol is not the id: keep the id
            attrs.metadata.set({"semloc": {"id": room}})
        graph.add_node(ROOMS_LAYER, spark.NodeSymbol(letter, index), attrs)
        for obj in objects:
            graph.insert_edge(spark.NodeSymbol(letter, index), spark.NodeSymbol(*symbols[obj.id]))


def _attributes(spark: Any, obj: SemanticObject, number: int, symbol: str) -> Any:
    attrs = spark.ObjectNodeAttributes()
    attrs.position = np.asarray(obj.position, dtype=float)
    attrs.semantic_label = number
    attrs.name = obj.label
    if obj.size is not None:
        rotation = np.eye(3) if obj.rotation is None else obj.rotation
        attrs.bounding_box = spark.BoundingBox(
            spark.BoundingBoxType.OBB, np.asarray(obj.size, np.float32),
            np.asarray(obj.position, np.float32), np.asarray(rotation, np.float32),
        )  # fmt: skip
    own: dict[str, Any] = {}
    if obj.id != symbol:  # the node's symbol is not the id: keep the id
        own["id"] = obj.id
    if obj.extra.get("missing") is True:
        own["missing"] = True
    if own:
        attrs.metadata.set({"semloc": own})
    return attrs


def _kept_symbol(obj: SemanticObject) -> str | None:
    kept = obj.extra.get("dsg")
    symbol = kept.get("symbol") if isinstance(kept, dict) else None
    return symbol if isinstance(symbol, str) and SYMBOL.match(symbol) else None


def _symbols(objmap: ObjectMap) -> dict[str, tuple[str, int]]:
    """A node symbol per object: the one it came with, its id if that is a symbol, else the
    next free `O(n)`."""
    chosen: dict[str, tuple[str, int]] = {}
    taken: set[tuple[str, int]] = set()
    for obj in objmap:
        text = _kept_symbol(obj) or (obj.id if SYMBOL.match(obj.id) else None)
        if text is not None:
            letter, number = SYMBOL.match(text).groups()  # type: ignore[union-attr]
            if (letter, int(number)) not in taken:
                chosen[obj.id] = (letter, int(number))
                taken.add(chosen[obj.id])
    used = {n for letter, n in chosen.values() if letter == "O"}
    free = (n for n in range(10**9) if n not in used)
    for obj in objmap:
        if obj.id not in chosen:
            chosen[obj.id] = ("O", next(free))
    return chosen


def _label_numbers(objmap: ObjectMap) -> dict[str, int]:
    """A label-space number per label: the graph's where the map came from one, else new."""
    numbers: dict[str, int] = {}
    for obj in objmap:
        kept = obj.extra.get("dsg")
        number = kept.get("semantic_label") if isinstance(kept, dict) else None
        if isinstance(number, int) and obj.label not in numbers and number not in numbers.values():
            numbers[obj.label] = number
    taken = set(numbers.values())
    free = (n for n in range(10**9) if n not in taken)
    for label in sorted(set(objmap.labels)):
        if label not in numbers:
            numbers[label] = next(free)
    return numbers
