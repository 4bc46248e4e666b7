"""Spark-DSG scene graphs: graphs built with spark-dsg's own API convert to maps (ids, label
names, positions, boxes, mesh points), maps export to graphs and back without loss (property
test), update-map's flags travel, objects keep their rooms both ways, and bad graphs end in one
line with exit 2."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

spark = pytest.importorskip("spark_dsg")

import semloc  # noqa: E402
from semloc.cli import main  # noqa: E402
from semloc.io.dsg import dsg_bytes, load_dsg  # noqa: E402
from semloc.maps import ObjectMap, SemanticObject  # noqa: E402

LABELSPACE = {3: "chair", 5: "table", 9: "couch"}


def hydra_graph(path, with_mesh=True, labelspace=True):
    """A small graph as Hydra writes them: objects O(n) with label numbers, boxes and mesh
    connections, a label space, and a place node (not an object)."""
    graph = spark.DynamicSceneGraph()
    rng = np.random.default_rng(1)
    vertices = []
    for n, (number, centre) in enumerate([(3, [1, 2, 0.4]), (5, [3, -1, 0.5]), (9, [0, 0, 0.45])]):
        attrs = spark.ObjectNodeAttributes()
        attrs.position = np.array(centre, float)
        attrs.semantic_label = number
        yaw = 0.3 * n
        R = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
        size = np.array([0.5 + n, 0.6, 0.9], np.float32)
        attrs.bounding_box = spark.BoundingBox(spark.BoundingBoxType.OBB, size,
                                               np.array(centre, np.float32), R.astype(np.float32))  # fmt: skip
        points = np.array(centre) + rng.uniform(-0.2, 0.2, (5 + n, 3))
        attrs.mesh_connections = list(range(len(vertices), len(vertices) + len(points)))
        vertices.extend(points)
        graph.add_node(spark.DsgLayers.OBJECTS, spark.NodeSymbol("O", 10 + n), attrs)
    place = spark.PlaceNodeAttributes()
    place.position = np.zeros(3)
    graph.add_node(spark.DsgLayers.PLACES, spark.NodeSymbol("p", 0), place)
    if labelspace:
        graph.set_labelspace(spark.Labelspace(LABELSPACE), 2, 0)
    if with_mesh:
        mesh = spark.Mesh()
        mesh.resize_vertices(len(vertices))
        for i, p in enumerate(vertices):
            mesh.set_pos(i, np.asarray(p, np.float32))
        graph.mesh = mesh
    graph.save(str(path), True)
    return graph, np.asarray(vertices, np.float32)


def test_convert_dsg_reads_the_object_layer(tmp_path):
    _, vertices = hydra_graph(tmp_path / "scene.json")
    assert main(["convert", "dsg", str(tmp_path / "scene.json"), "-o", str(tmp_path / "m.json"),
                 "--voxel", "0"]) == 0  # fmt: skip
    objmap = semloc.load_map(tmp_path / "m.json")
    assert list(objmap.ids) == ["O(10)", "O(11)", "O(12)"]
    assert list(objmap.labels) == ["chair", "table", "couch"]  # the graph's names, kept
    assert list(objmap.up) == [0, 0, 1]
    chair = objmap.get("O(10)")
    assert np.allclose(chair.position, [1, 2, 0.4]) and np.allclose(chair.size, [0.5, 0.6, 0.9])
    couch = objmap.get("O(12)")
    assert np.allclose(couch.rotation[:2, :2], [[np.cos(0.6), -np.sin(0.6)],
                                                [np.sin(0.6), np.cos(0.6)]], atol=1e-6)  # fmt: skip
    assert np.allclose(chair.points, vertices[:5], atol=1e-6)
    assert len(couch.points) == 7


def test_label_numbers_without_names_get_them_from_a_label_map(tmp_path, capsys):
    hydra_graph(tmp_path / "old.json", labelspace=False)
    assert list(load_dsg(tmp_path / "old.json").labels) == ["class_3", "class_5", "class_9"]
    (tmp_path / "names.json").write_text(json.dumps({"3": "chair", "9": "sofa"}))
    argv = ["convert", "dsg", str(tmp_path / "old.json"), "-o", str(tmp_path / "m.json"),
            "--label-map", str(tmp_path / "names.json")]  # fmt: skip
    assert main(argv) == 0
    assert list(semloc.load_map(tmp_path / "m.json").labels) == ["chair", "class_5", "sofa"]
    (tmp_path / "bad.json").write_text(json.dumps({"chair": "sofa"}))
    capsys.readouterr()
    assert main(argv[:-1] + [str(tmp_path / "bad.json")]) == 2
    _one_error_line(capsys, "bad.json", "label numbers")


def test_a_graph_goes_to_a_map_and_back_unchanged(tmp_path):
    hydra_graph(tmp_path / "scene.json")
    objmap = load_dsg(tmp_path / "scene.json")
    (tmp_path / "again.json").write_bytes(dsg_bytes(objmap, tmp_path / "again.json"))
    before = spark.DynamicSceneGraph.load(str(tmp_path / "scene.json"))
    after = spark.DynamicSceneGraph.load(str(tmp_path / "again.json"))
    assert after.get_labelspace(2, 0).labels_to_names == LABELSPACE
    nodes = {str(n.id): n.attributes for n in after.get_layer(2).nodes}
    vertices_before = before.mesh.get_vertices()[:3].T
    vertices_after = after.mesh.get_vertices()[:3].T
    for node in before.get_layer(2).nodes:
        a, b = node.attributes, nodes[str(node.id)]
        assert a.semantic_label == b.semantic_label
        assert np.allclose(a.position, b.position)
        assert np.allclose(a.bounding_box.dimensions, b.bounding_box.dimensions)
        assert np.allclose(a.bounding_box.world_R_center, b.bounding_box.world_R_center)
        assert np.allclose(vertices_before[list(a.mesh_connections)],
                           vertices_after[list(b.mesh_connections)])  # fmt: skip
        assert b.metadata.get() in ({}, None)  # a graph's own ids need no semloc note


ids = st.text("abcxyz0123456789_:-()O", min_size=1, max_size=8).filter(lambda s: s.strip())
labels = st.sampled_from(["chair", "table", "couch", "lamp", "O(3)"])
xyz = st.lists(st.floats(-20, 20, allow_nan=False, width=32), min_size=3, max_size=3)


@st.composite
def maps(draw):
    chosen = draw(st.lists(ids, min_size=1, max_size=6, unique=True))
    objects = []
    for object_id in chosen:
        size = draw(st.none() | st.lists(st.floats(0.0625, 4, width=32), min_size=3, max_size=3))
        points = draw(st.none() | st.lists(xyz, min_size=1, max_size=5))
        extra = {"missing": True} if draw(st.booleans()) else {}
        room = draw(st.none() | st.sampled_from(["R(1)", "R(2)", "kitchen", "O(3)", "p(0)"]))
        if room is not None:
            extra["room"] = room
        objects.append(SemanticObject(object_id, draw(labels), draw(xyz), size,
                                      None if size is None else np.eye(3), points, extra=extra))  # fmt: skip
    return ObjectMap(objects, up=[0, 0, 1], name="m")


@given(maps())
@settings(max_examples=25, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_a_map_goes_to_a_graph_and_back_unchanged(tmp_path, objmap):
    path = tmp_path / "g.json"
    path.write_bytes(dsg_bytes(objmap, path))
    back = load_dsg(path)
    assert sorted(back.ids) == sorted(objmap.ids)
    for obj in objmap:
        got = back.get(obj.id)
        assert got.label == obj.label
        assert np.allclose(got.position, obj.position, atol=1e-5)
        assert (got.size is None) == (obj.size is None)
        if obj.size is not None:
            assert np.allclose(got.size, obj.size, atol=1e-5)
        assert (got.points is None) == (obj.points is None)
        if obj.points is not None:
            assert np.allclose(got.points, obj.points, atol=1e-5)
        assert got.extra.get("missing") == obj.extra.get("missing")
        assert got.extra.get("room") == obj.extra.get("room")


def test_export_dsg_and_convert_round_trip_through_the_cli(tmp_path):
    hydra_graph(tmp_path / "scene.json")
    m1, g2, m2 = tmp_path / "m1.json", tmp_path / "g2.sparkdsg", tmp_path / "m2.json"
    assert (
        main(["convert", "dsg", str(tmp_path / "scene.json"), "-o", str(m1), "--voxel", "0"]) == 0
    )
    assert main(["export", str(m1), "--format", "dsg", "-o", str(g2)]) == 0  # binary
    assert main(["convert", "dsg", str(g2), "-o", str(m2), "--voxel", "0"]) == 0
    a, b = json.loads(m1.read_text()), json.loads(m2.read_text())
    assert a["objects"] == b["objects"]


def _one_error_line(capsys, *fragments):
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("semloc: error: "), err
    for fragment in fragments:
        assert fragment in err, err


def test_bad_graphs_end_in_one_line(tmp_path, capsys):
    hydra_graph(tmp_path / "scene.json")
    data = (tmp_path / "scene.json").read_bytes()
    empty = spark.DynamicSceneGraph()
    empty.save(str(tmp_path / "empty.json"), True)
    cases = {"cut.json": data[: len(data) // 2], "list.json": b"[1, 2]",
             "junk.sparkdsg": b"not a graph"}  # fmt: skip
    for name, content in cases.items():
        (tmp_path / name).write_bytes(content)
    for name, fragment in [("cut.json", "not valid JSON"), ("list.json", "not a Spark-DSG"),
                           ("junk.sparkdsg", "not a readable Spark-DSG"),
                           ("empty.json", "no objects")]:  # fmt: skip
        capsys.readouterr()
        out = tmp_path / "out.json"
        assert main(["convert", "dsg", str(tmp_path / name), "-o", str(out)]) == 2
        _one_error_line(capsys, name, fragment)
        assert not out.exists()


def test_export_dsg_refuses_what_does_not_apply_and_overwriting_its_input(tmp_path, capsys):
    objmap = ObjectMap([SemanticObject("a", "chair", [0, 0, 0])], up=[0, 0, 1])
    semloc.save_map(objmap, tmp_path / "m.json")
    capsys.readouterr()
    assert main(["export", str(tmp_path / "m.json"), "--format", "dsg", "-o",
                 str(tmp_path / "m.json")]) == 2  # fmt: skip
    _one_error_line(capsys, "would overwrite")
    assert main(["export", str(tmp_path / "m.json"), "--format", "dsg", "-o",
                 str(tmp_path / "g.json"), "--local", str(tmp_path / "m.json")]) == 2  # fmt: skip
    _one_error_line(capsys, "--format dsg writes MAP alone")
    assert not (tmp_path / "g.json").exists()


def test_update_map_flags_travel_to_the_graph(tmp_path):
    objmap = ObjectMap([SemanticObject("O(4)", "chair", [0, 0, 0], extra={"missing": True}),
                        SemanticObject("new:l7", "lamp", [1, 0, 0])], up=[0, 0, 1])  # fmt: skip
    path = tmp_path / "g.json"
    path.write_bytes(dsg_bytes(objmap, path))
    graph = spark.DynamicSceneGraph.load(str(path))
    nodes = {str(n.id): n.attributes.metadata.get() for n in graph.get_layer(2).nodes}
    assert nodes["O(4)"] == {"semloc": {"missing": True}}
    assert nodes["O(0)"] == {"semloc": {"id": "new:l7"}}


def rooms_graph(path):
    """Two rooms as Hydra links them: objects under places under rooms, one object under a
    room directly, one under both a place of R(1) and the room R(2) (the room wins), one under a place with
    no room, one under nothing; a building above the rooms."""
    graph = spark.DynamicSceneGraph()

    def add(layer, letter, index, attrs, position):
        attrs.position = np.asarray(position, float)
        graph.add_node(layer, spark.NodeSymbol(letter, index), attrs)

    for index, position in [(1, [0, 0, 1]), (2, [5, 0, 1])]:
        add(spark.DsgLayers.ROOMS, "R", index, spark.RoomNodeAttributes(), position)
    add(spark.DsgLayers.BUILDINGS, "B", 0, spark.RoomNodeAttributes(), [2.5, 0, 1])
    for index, position in enumerate([[0, 0, 1], [1, 0, 1], [5, 0, 1], [9, 9, 1]]):
        add(spark.DsgLayers.PLACES, "p", index, spark.PlaceNodeAttributes(), position)
    add(spark.DsgLayers.PLACES, "P", 7, spark.PlaceNodeAttributes(), [0, 1, 1])  # sorts first
    for index in range(7):
        attrs = spark.ObjectNodeAttributes()
        attrs.semantic_label = 3
        add(spark.DsgLayers.OBJECTS, "O", index, attrs, [index, 0, 0.5])
    edges = [("B0", "R1"), ("B0", "R2"), ("R1", "p0"), ("R1", "p1"), ("R2", "p2"),
             ("p0", "O0"), ("p1", "O1"), ("p2", "O2"), ("R2", "O3"),
             ("R1", "P7"), ("P7", "O4"), ("R2", "O4"), ("p3", "O5")]  # fmt: skip
    for parent, child in edges:
        assert graph.insert_edge(spark.NodeSymbol(parent[0], int(parent[1:])),
                                 spark.NodeSymbol(child[0], int(child[1:])))  # fmt: skip
    graph.set_labelspace(spark.Labelspace(LABELSPACE), 2, 0)
    graph.save(str(path), True)


ROOMS = {"O(0)": "R(1)", "O(1)": "R(1)", "O(2)": "R(2)", "O(3)": "R(2)", "O(4)": "R(2)"}


def test_objects_keep_the_room_they_are_in(tmp_path):
    rooms_graph(tmp_path / "scene.json")
    objmap = load_dsg(tmp_path / "scene.json")
    assert {o.id: o.extra.get("room") for o in objmap if "room" in o.extra} == ROOMS
    assert objmap.get("O(0)").extra["dsg"] == {"symbol": "O(0)", "semantic_label": 3}
    assert "room" not in objmap.get("O(5)").extra and "room" not in objmap.get("O(6)").extra
    # the map file keeps the rooms (an object key semloc does not know is kept)
    assert (
        main(["convert", "dsg", str(tmp_path / "scene.json"), "-o", str(tmp_path / "m.json")]) == 0
    )
    saved = semloc.load_map(tmp_path / "m.json")
    assert {o.id: o.extra["room"] for o in saved if "room" in o.extra} == ROOMS


def test_rooms_go_to_a_graph_and_back(tmp_path):
    rooms_graph(tmp_path / "scene.sparkdsg")
    objmap = load_dsg(tmp_path / "scene.sparkdsg")
    path = tmp_path / "again.sparkdsg"
    path.write_bytes(dsg_bytes(objmap, path))
    graph = spark.DynamicSceneGraph.load(str(path))
    rooms = {str(n.id): n for n in graph.get_layer(spark.DsgLayers.ROOMS).nodes}
    assert sorted(rooms) == ["R(1)", "R(2)"]
    assert np.allclose(rooms["R(1)"].attributes.position, [0.5, 0, 0.5])  # mean of O(0), O(1)
    assert np.allclose(rooms["R(2)"].attributes.position, [3, 0, 0.5])
    children = {str(spark.NodeSymbol(c)) for c in rooms["R(2)"].children()}
    assert children == {"O(2)", "O(3)", "O(4)"}
    assert rooms["R(1)"].attributes.metadata.get() in ({}, None)
    back = load_dsg(path)
    assert {o.id: o.extra["room"] for o in back if "room" in o.extra} == ROOMS
    # a room id that is no free symbol gets the next free R(n) and keeps its id
    renamed = ObjectMap([SemanticObject("R(0)", "chair", [0, 0, 0], extra={"room": "kitchen"}),
                         SemanticObject("b", "table", [2, 0, 0], extra={"room": "R(0)"})],
                        up=[0, 0, 1])  # fmt: skip
    path.write_bytes(dsg_bytes(renamed, path))
    graph = spark.DynamicSceneGraph.load(str(path))
    notes = {str(n.id): n.attributes.metadata.get() for n in graph.get_layer(4).nodes}
    assert notes == {"R(1)": {"semloc": {"id": "kitchen"}}, "R(2)": {"semloc": {"id": "R(0)"}}}
    back = load_dsg(path)
    assert [back.get(i).extra["room"] for i in ("R(0)", "b")] == ["kitchen", "R(0)"]
