"""Which map objects an answer counts missing (`Support.missing_ids`): exactly those a look
shows and nobody detected, in the answer, its JSON, the service's answer model, the CLI's
support line and the Foxglove view; none without coverage."""

from __future__ import annotations

import io

import numpy as np
import pytest
from rich.console import Console
from test_tracking_rules import ALL_AROUND, claimed, local, room

from semloc import Localizer, ObjectMap, schema
from semloc.cli.render import print_result
from semloc.results import Result, Support


@pytest.fixture(scope="module")
def building() -> ObjectMap:
    return ObjectMap(room(), up=[0, 0, 1])


def test_a_search_names_the_map_objects_its_look_shows_that_were_not_detected(building):
    localizer = Localizer(building, local_up=[0, 0, 1])
    today = local(room(drop=(3, 8)))  # two of ten gone
    result = localizer.update(today, coverage=ALL_AROUND)
    assert result.status == "localized" and result.support is not None
    assert result.support.n_missing == 2 and result.support.missing_ids == ("a3", "a8")
    assert result.support.n_pairs == 8 and result.support.seen == (0, 0)  # the 8 detected


def test_a_tracked_claim_names_them_too_and_without_coverage_none(building):
    localizer = claimed(building)
    assert localizer.update([]).support.missing_ids is None  # no coverage: no ids
    result = localizer.update(local(room(drop=(5,))), coverage=ALL_AROUND)
    assert result.status == "localized" and result.support.tracked
    assert result.support.n_missing == 1 and result.support.missing_ids == ("a5",)
    everything = localizer.update(local(room()), coverage=ALL_AROUND)
    assert everything.support.n_missing == 0 and everything.support.missing_ids == ()


def test_the_ids_round_trip_through_the_json_and_the_answer_schema(building):
    localizer = Localizer(building, local_up=[0, 0, 1])
    result = localizer.update(local(room(drop=(3, 8))), coverage=ALL_AROUND)
    document = result.to_dict()
    assert document["support"]["missing_ids"] == ["a3", "a8"]
    assert Result.from_dict(document).support == result.support
    assert schema.Support.model_validate(document["support"]).missing_ids == ["a3", "a8"]
    plain = Support(3, (0, 1), 0, 0.0)
    assert plain.to_dict()["missing_ids"] is None
    assert Support.of_model(schema.Support.model_validate(plain.to_dict())) == plain
    old = {k: v for k, v in plain.to_dict().items() if k != "missing_ids"}  # an older answer
    assert Support.of_model(schema.Support.model_validate(old)) == plain
    with pytest.raises(ValueError, match="missing_ids"):
        schema.Support.model_validate({**plain.to_dict(), "missing_ids": [[1], 2]})


def test_the_cli_prints_the_support_line_with_what_was_missing(building):
    localizer = Localizer(building, local_up=[0, 0, 1])
    result = localizer.update(local(room(drop=(3, 8))), coverage=ALL_AROUND)
    out = io.StringIO()
    print_result(result, Console(file=out, width=120))
    [line] = [x for x in out.getvalue().splitlines() if x.startswith("support:")]
    expected = result.support.n_expected
    pairs = result.support.n_pairs
    assert line == f"support: {pairs} pairs; 2 of {expected} map objects in view missing: a3, a8"
    plain = Localizer(building, local_up=[0, 0, 1]).update(local(room()))
    out = io.StringIO()
    print_result(plain, Console(file=out, width=120))
    assert "support:" not in out.getvalue()  # no coverage: nothing to say


def test_the_foxglove_view_draws_the_missing_map_objects(building):
    pytest.importorskip("foxglove", reason="foxglove-sdk (the viz extra) is not installed")
    pytest.importorskip("websockets", reason="websockets (the viz extra) is not installed")
    from semloc.pictures.live import FoxgloveView, missing_boxes

    localizer = Localizer(building, local_up=[0, 0, 1])
    result = localizer.update(local(room(drop=(3, 8))), coverage=ALL_AROUND)
    boxes = missing_boxes(result, building)
    assert [b.text for b in boxes] == ["missing a3", "missing a8"]
    for box, gid in zip(boxes, ("a3", "a8")):
        np.testing.assert_allclose(box.T[:3, 3], building.get(gid).position)
        np.testing.assert_allclose(box.size, building.get(gid).size + 0.1)
    plain = Localizer(building, local_up=[0, 0, 1]).update(local(room()))
    assert missing_boxes(plain, building) == []
    view = FoxgloveView(building, port=0)
    try:
        scene = view._local_scene(result, localizer.local_map).encode()
        status = view._status(result).encode()
        empty = view._local_scene(plain, localizer.local_map).encode()
    finally:
        view.close()
    assert b"missing a3" in scene and b"missing a8" in scene
    assert b"missing" in empty and b"missing a" not in empty  # an empty entity replaces it
    expected = result.support.n_expected
    assert f"; 2 of {expected} map objects in view missing".encode() in status
