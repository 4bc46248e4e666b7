"""Bad input ends in one line `semloc: error: ...` and exit status 2, never a traceback: the
three inputs of issue 39 and their siblings (every numeric option's range, every field of a
result file, pose files of the wrong kind, files given where a map goes)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import typer.main
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from semloc.cli import app, main
from semloc.cli.app import CliError
from semloc.cli.files import read_pose, read_result

IDENTITY = np.eye(4).tolist()
CAPTURE = [HealthCheck.too_slow, HealthCheck.function_scoped_fixture]
"""capsys is shared by a property's examples: each reads (and so empties) it first."""


def valid_map(n: int = 6, points: int = 8) -> dict:
    """A small valid map document: objects on a ring, each with a few points."""
    labels = ["chair", "table", "lamp"]
    objects = []
    for i in range(n):
        centre = np.array([3 * np.cos(i), 3 * np.sin(i) + 0.3 * i, 0.4])
        cloud = centre + 0.2 * np.sin(np.arange(points * 3) + i).reshape(points, 3)
        objects.append({"id": f"o{i}", "label": labels[i % 3], "position": centre.tolist(),
                        "points": cloud.tolist(), "seen": i})  # fmt: skip
    return {"format": "semloc-map", "version": 1, "up": [0, 0, 1], "objects": objects}


def _one_error_line(capsys, *fragments: str) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("semloc: error: "), err
    for fragment in fragments:
        assert fragment in err, err
    return err


def _write(path: Path, document: object) -> Path:
    path.write_text(json.dumps(document))
    return path


@pytest.fixture
def good_map(tmp_path) -> Path:
    return _write(tmp_path / "map.json", valid_map())


# The three inputs of the issue -----------------------------------------------------------------
def test_map_whose_up_overflows_is_refused(tmp_path, capsys):
    document = {**valid_map(), "up": [1e308, 1e308, 0]}
    bad = _write(tmp_path / "up.json", document)
    assert main(["view", str(bad), "-o", str(tmp_path / "v.png")]) == 2
    _one_error_line(capsys, "up.json", "up ", "too large")
    assert not (tmp_path / "v.png").exists()


def test_view_result_whose_pairs_is_a_number(tmp_path, good_map, capsys):
    result = {"status": "localized", "pose": IDENTITY, "hypotheses": [{"rank": 1, "pairs": 5}]}
    path = _write(tmp_path / "r.json", result)
    assert main(["view", str(good_map), "--result", str(path), "-o", str(tmp_path / "v.png")]) == 2
    _one_error_line(capsys, "r.json", "'hypotheses[0].pairs' must be a valid list")


def test_crop_negative_seed(tmp_path, good_map, capsys):
    out = tmp_path / "c.json"
    argv = ["crop", str(good_map), "--center", "0", "0", "0", "--radius", "5", "-o", str(out)]
    assert main([*argv, "--seed", "-1"]) == 2
    _one_error_line(capsys, "--seed", "greater than or equal to 0")
    assert not out.exists()


# Numeric options: every one has a range, and a value outside it is one line -------------------
VALIDATED_ELSEWHERE = {
    ("localize", "gamma"), ("localize", "delta"), ("localize", "tolerance"),
    ("localize", "descriptor_delta"), ("localize", "top_k"),  # LocalizerConfig (pydantic)
    ("demo", "gamma"),  # DemoConfig (pydantic)
    ("align", "gamma"),  # LocalizerConfig (pydantic)
    ("crop", "radius"), ("crop", "center"),  # positive / finite checks of the command
    ("localize", "near"), ("localize", "radius"),  # the position prior (semloc.Prior) checks them
}  # fmt: skip
"""Numeric options whose range a settings model or the command checks (tested below)."""

REQUIRED = {
    "simulate": ["out_folder"],
    "view": ["map.json"],
    "localize": ["g.json", "l.json"],
    "convert": ["scannet", "scene", "-o", "m.json"],
    "crop": ["map.json", "--center", "0", "0", "0", "--radius", "1", "-o", "c.json"],
    "export": ["map.json", "-o", "m.ply"],
}
"""Arguments that let each command get as far as parsing its options."""


def _numeric_options() -> list[tuple[str, object]]:
    command = typer.main.get_command(app)
    found = []
    for name, sub in command.commands.items():
        for param in sub.params:
            annotation = param.type_descriptor.annotation
            numeric = annotation in (int, float, int | None, float | None)
            if numeric or annotation == tuple[float, float, float]:
                found.append((name, param))
    return found


NUMERIC = _numeric_options()
RANGED = [(c, p) for c, p in NUMERIC if (c, p.name) not in VALIDATED_ELSEWHERE]


def test_every_numeric_option_has_a_range():
    """A new numeric option declares min and max (typer shows them in --help and refuses
    values outside in one line), or its command's settings check it (`VALIDATED_ELSEWHERE`)."""
    assert len(NUMERIC) > 20
    unbounded = [f"{c} --{p.name}" for c, p in RANGED if p.min is None or p.max is None]
    assert not unbounded, unbounded
    stale = VALIDATED_ELSEWHERE - {(c, p.name) for c, p in NUMERIC}
    assert not stale, stale


@pytest.mark.slow
@settings(max_examples=60, suppress_health_check=CAPTURE)
@given(option=st.sampled_from(RANGED), data=st.data())
def test_numeric_option_out_of_range_is_one_line(option, data, capsys):
    """Any value below the minimum or above the maximum: exit 2 naming the option (typer
    checks the range while parsing, so no command starts its work)."""
    command, param = option
    flag = param.opts[0]
    whole = param.type_descriptor.annotation in (int, int | None)
    low, high = param.min, param.max
    if whole:
        outside = st.integers(max_value=low - 1) | st.integers(min_value=high + 1)
    else:
        span = max(abs(high), 1.0)
        outside = st.floats(max_value=low - span * 1e-6, allow_infinity=False) | st.floats(
            min_value=high + span * 1e-6, allow_infinity=False
        )
    value = data.draw(outside)
    capsys.readouterr()
    assert main([command, *REQUIRED.get(command, []), flag, str(value)]) == 2
    _one_error_line(capsys, flag)


@settings(max_examples=25, suppress_health_check=CAPTURE)
@given(
    option=st.sampled_from(["--gamma", "--delta", "--tolerance", "--descriptor-delta", "--top-k"]),
    value=st.integers(-(10**30), 10**30) | st.floats(allow_nan=False, allow_infinity=False),
)
def test_localize_settings_options_are_checked(tmp_path_factory, option, value, capsys):
    """The options LocalizerConfig checks: any number runs or is refused in one line."""
    folder = tmp_path_factory.mktemp("settings")
    good = _write(folder / "m.json", valid_map(n=4, points=0))
    text = str(int(value)) if option == "--top-k" else str(value)
    capsys.readouterr()
    code = main(["localize", str(good), str(good), option, text, "--format", "json"])
    assert code in (0, 2)
    if code == 2:
        _one_error_line(capsys, option.removeprefix("--").replace("-", "_"))


@settings(max_examples=25, suppress_health_check=CAPTURE)
@given(
    radius=st.floats() | st.integers(-(10**30), 10**30),
    near=st.tuples(st.floats(), st.floats(), st.floats()),
)
def test_localize_prior_options_are_checked(tmp_path_factory, radius, near, capsys):
    """--near X Y Z --radius R: any numbers run or are refused in one line naming them."""
    folder = tmp_path_factory.mktemp("prior")
    good = _write(folder / "m.json", valid_map(n=4, points=0))
    capsys.readouterr()
    argv = ["localize", str(good), str(good), "--near", *map(str, near), "--radius", str(radius)]
    code = main([*argv, "--format", "json"])
    assert code in (0, 2)
    if code == 2:
        _one_error_line(capsys, "--")


def test_settings_file_seed_is_checked(tmp_path, good_map, capsys):
    settings_file = _write(tmp_path / "s.json", {"pose": {"seed": -1}})
    assert main(["localize", str(good_map), str(good_map), "--config", str(settings_file)]) == 2
    _one_error_line(capsys, "pose.seed")


@pytest.mark.parametrize(
    ("values", "where"),
    [(["1", "2"], "end"), (["1", "2"], "middle"), (["1", "2", "x"], "end"), (["1"], "middle")],
)
def test_crop_center_needs_three_numbers(tmp_path, good_map, capsys, values, where):
    center = ["--center", *values]
    rest = ["--radius", "5", "-o", str(tmp_path / "c.json")]
    argv = ["crop", str(good_map), *(rest + center if where == "end" else center + rest)]
    assert main(argv) == 2
    _one_error_line(capsys, "'--center': needs 3 numbers")


# Result files: every field of the wrong type is one line naming it -----------------------------
GOOD_RESULT = {
    "status": "ambiguous",
    "pose": IDENTITY,
    "hypotheses": [{"rank": 1, "pairs": [{"global": "o0", "local": "o1"}], "pose": IDENTITY}],
}


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"status": 3}, "'status'"),
        ({"status": "maybe"}, "'status'"),
        ({"pose": "identity"}, "pose"),
        ({"pose": [[1, 0, 0, 1e300], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}, "translation"),
        ({"hypotheses": 5}, "'hypotheses' must be a valid list"),
        ({"hypotheses": {"rank": 1}}, "'hypotheses' must be a valid list"),
        ({"hypotheses": [5]}, "'hypotheses[0]' must be an object"),
        ({"hypotheses": [{"pairs": "o0-o1"}]}, "'hypotheses[0].pairs' must be a valid list"),
        ({"hypotheses": [{"pairs": [["o0", "o1"]]}]}, "'hypotheses[0].pairs[0]' must be an object"),
        (
            {"hypotheses": [{"pairs": [{"global": "o0"}]}]},
            "'hypotheses[0].pairs[0].local' is required",
        ),
        ({"hypotheses": [{"pairs": [{"global": True, "local": "a"}]}]}, "pairs[0]"),
        ({"hypotheses": [{"pairs": [], "pose": 7}]}, "hypotheses[0].pose"),
    ],
)
def test_result_field_of_wrong_type(tmp_path, good_map, capsys, change, field):
    path = _write(tmp_path / "r.json", {**GOOD_RESULT, **change})
    for argv in (
        ["view", str(good_map), "--result", str(path), "-o", str(tmp_path / "v.png")],
        ["export", str(good_map), "--result", str(path), "--local", str(good_map),
         "-o", str(tmp_path / "e.ply")],
    ):  # fmt: skip
        assert main(argv) == 2
        _one_error_line(capsys, "r.json", field)
    assert not list(tmp_path.glob("*.png")) and not list(tmp_path.glob("*.ply"))


def test_result_file_read_whole(tmp_path):
    answer = read_result(_write(tmp_path / "r.json", GOOD_RESULT))
    assert answer.status == "ambiguous" and answer.pairs == [("o0", "o1")]
    assert np.allclose(answer.pose, np.eye(4)) and np.allclose(answer.hypotheses[0][0], np.eye(4))
    truth = read_result(_write(tmp_path / "gt.json", {"T_global_local": IDENTITY}))
    assert truth.status is None and truth.pairs == [] and np.allclose(truth.pose, np.eye(4))


JSON = st.recursive(
    st.none()
    | st.booleans()
    | st.integers()
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=5),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4)
    ),
    max_leaves=12,
)
PAIR = st.fixed_dictionaries({"global": JSON, "local": JSON}) | JSON
HYPOTHESIS = st.fixed_dictionaries({}, optional={"pairs": st.lists(PAIR, max_size=3) | JSON,
                                                 "pose": st.just(IDENTITY) | JSON})  # fmt: skip
RESULT = st.fixed_dictionaries(
    {"pose": st.just(IDENTITY) | st.none() | JSON},
    optional={"status": st.sampled_from(["localized", "failed"]) | JSON,
              "hypotheses": st.lists(HYPOTHESIS, max_size=3) | JSON},
)  # fmt: skip


@settings(max_examples=200, suppress_health_check=CAPTURE)
@given(RESULT)
def test_any_result_document_is_read_or_refused_in_one_line(tmp_path_factory, document):
    path = tmp_path_factory.mktemp("result") / "r.json"
    path.write_text(json.dumps(document, allow_nan=False))
    try:
        answer = read_result(path)
    except CliError as exc:
        assert str(exc).startswith(str(path)) and "\n" not in str(exc)
        return
    assert answer.pose is None or answer.pose.shape == (4, 4)
    assert all(isinstance(g, str) and isinstance(l, str) for g, l in answer.pairs)


# Files of the wrong kind ------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("document", "kind"),
    [
        (valid_map(), "a semloc map"),
        (GOOD_RESULT, "a localization result"),
        ({"objects": []}, "an object without it"),
    ],
)
def test_gt_names_the_key_it_looked_for(tmp_path, good_map, capsys, document, kind):
    path = _write(tmp_path / "gt.json", document)
    assert main(["localize", str(good_map), str(good_map), "--gt", str(path)]) == 2
    _one_error_line(capsys, "gt.json", "no 'T_global_local' key", kind)
    with pytest.raises(CliError, match="T_global_local"):
        read_pose(path)


@pytest.mark.parametrize(
    ("name", "content", "hint"),
    [
        ("r.json", json.dumps(GOOD_RESULT), "a localization result: give it to view or export"),
        ("a.json", json.dumps({"sceneId": "s", "segGroups": []}), "semloc convert scannet"),
        ("gt.json", json.dumps({"T_global_local": IDENTITY}), "give it with --gt"),
        ("s.json", json.dumps({"gamma": 0.7}), "give it with --config"),
        ("p.npz", None, "a .npz holds point arrays"),
        ("m.ply", b"ply\nformat binary_little_endian 1.0\n\xff\xfe", "a .ply is a mesh"),
    ],
)
def test_not_a_map_gets_a_hint(tmp_path, good_map, capsys, name, content, hint):
    path = tmp_path / name
    if content is None:
        np.savez(path, o0=np.zeros((3, 3)))
    else:
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
    assert main(["localize", str(path), str(good_map)]) == 2
    _one_error_line(capsys, name, hint)


def test_an_option_with_an_optional_value_takes_its_default_alone():
    from semloc.cli.app import with_optional_values

    assert with_optional_values(["demo", "--foxglove"]) == ["demo", "--foxglove", "8765"]
    assert with_optional_values(["demo", "--foxglove", "--size", "tiny"]) == [
        "demo", "--foxglove", "8765", "--size", "tiny"]  # fmt: skip
    assert with_optional_values(["demo", "--foxglove", "9000"]) == ["demo", "--foxglove", "9000"]
    assert with_optional_values(["demo", "--foxglove", "-1"]) == ["demo", "--foxglove", "-1"]
