"""The service's answers and `semloc localize --server` are the one answer schema
(`semloc.schema`): exactly its models, as the OpenAPI declares them."""

from __future__ import annotations

import json

from conftest import T_TRUE, view

from semloc import schema
from semloc.cli import main
from semloc.client import Client
from semloc.coverage import Coverage
from semloc.io import save_map
from semloc.priors import Prior
from semloc.results import Result

TABLE = [3, 4, 5, 6, 7, 8, 9]
ALL_AROUND = Coverage(pose=[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], range_m=8.0)


def test_a_localization_answer_is_exactly_a_localize_answer(serve, building):
    client = Client(serve().url)
    client.put_map("office", building)
    local = view(building, TABLE, T_TRUE)
    answer = client.localize("office", local, Prior(position=T_TRUE[:3, 3], radius=3.0))
    assert schema.problems(answer, schema.LocalizeAnswer) == []
    assert answer["labels"] and answer["prior"]["radius"] == 3.0
    assert Result.from_dict(answer).to_dict() == {
        key: value for key, value in answer.items() if key not in ("map_version", "localization_id")
    }


def test_every_session_answer_is_exactly_a_session_answer(serve, building):
    client = Client(serve().url)
    client.put_map("office", building)
    local = view(building, TABLE, T_TRUE)
    with client.session("office", up=local.up.tolist()) as session:
        for k, obj in enumerate(local):
            served = session.update([obj], stamp=10.0 + k)
            assert schema.problems(served, schema.SessionAnswer) == [], k
        served = session.update(list(local), stamp=20.0, coverage=ALL_AROUND)  # every object
        assert schema.problems(served, schema.SessionAnswer) == []
        (listed,) = client.sessions("office")
    assert served["support"]["n_expected"] is not None  # (with coverage)
    last = listed["last"]  # the latest answer in short, its best pairs in the answer's form
    assert last["status"] == served["status"] and last["stamp"] == 20.0
    assert last["pose"] == served["pose"] and last["update"] == served["update"]
    assert last["hypotheses"] == [{"pairs": served["hypotheses"][0]["pairs"]}]


def test_the_openapi_answers_are_the_schemas_models(serve):
    spec = Client(serve().url).request("GET", "/openapi.json")
    components = spec["components"]["schemas"]
    for name in ("LocalizeAnswer", "SessionAnswer", "Hypothesis", "Support", "Changes", "Step"):
        model = getattr(schema, name)
        declared = model.model_json_schema(mode="serialization")
        assert set(components[name]["properties"]) == set(declared["properties"]), name
        assert components[name]["required"] == declared["required"], name
    assert "n_pairs" in components["Support"]["required"]
    assert "outside_prior" not in components["Hypothesis"]["required"]  # (only with a prior)
    last = components["SessionInfo"]["properties"]["last"]["anyOf"][0]["$ref"]
    assert last.endswith("/LastAnswer")  # (a session's latest answer, typed)
    assert set(components["LastAnswer"]["required"]) == {"status", "pose", "map_version",
                                                         "hypotheses"}  # fmt: skip


def test_localize_on_a_server_writes_a_localize_answer(serve, building, tmp_path):
    server = serve()
    Client(server.url).put_map("office", building)
    local, truth, out = tmp_path / "local.json", tmp_path / "gt.json", tmp_path / "answer.json"
    save_map(view(building, TABLE, T_TRUE), local)
    truth.write_text(json.dumps({"T_global_local": T_TRUE.tolist()}))
    argv = ["localize", "office", str(local), "--server", server.url, "--gt", str(truth)]
    assert main([*argv, "--format", "json", "-o", str(out)]) == 0
    document = json.loads(out.read_text())
    assert schema.problems(document, schema.LocalizeAnswer) == []
    assert document["ground_truth"]["success"]
