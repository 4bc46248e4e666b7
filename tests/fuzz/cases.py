"""Hostile inputs for the fuzz suite: map files, importer scenes and options, each a `Case`.

A case writes its files into a folder and gives the `semloc` argv to run and the fragments one
of which the error line must name (a file of the case or an option).  The mutation corpus
starts from the small real-format scenes of `format_fixtures.py` (written here, never copied
from real data) and damages them deterministically from a seed.
"""

from __future__ import annotations

import functools
import json
import os
import random
import struct
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from format_fixtures import write_replica, write_rscan, write_scan2cad, write_scannet


@dataclass(frozen=True)
class Case:
    name: str
    setup: Callable[[Path], tuple[list[str], list[str]]]  # folder -> (argv, blame fragments)


def valid_map(n: int = 6, seed: int = 0, points: int = 30) -> dict:
    """A small valid map document (objects on a ring, each with a few points)."""
    rng = np.random.default_rng(seed)
    labels = ["chair", "table", "lamp", "sofa"]
    objects = []
    for i in range(n):
        centre = np.array([3 * np.cos(i), 3 * np.sin(i) + 0.3 * i, 0.4])
        objects.append({
            "id": f"o{i}", "label": labels[i % 4], "position": centre.round(3).tolist(),
            "size": [0.5, 0.6, 0.8],
            "points": (centre + rng.normal(0, 0.2, (points, 3))).round(3).tolist(), "seen": i % 3,
        })  # fmt: skip
    return {"format": "semloc-map", "version": 1, "name": "fuzz", "up": [0, 0, 1],
            "objects": objects}  # fmt: skip


def _write(path: Path, content: str | bytes | dict) -> Path:
    if isinstance(content, dict):
        content = json.dumps(content)
    if isinstance(content, str):
        content = content.encode("utf-8", "surrogatepass")
    path.write_bytes(content)
    return path


def npy_header(shape: tuple[int, ...], dtype: str = "<f8") -> bytes:
    """A version 1.0 .npy header declaring `shape` (no data need follow)."""
    text = f"{{'descr': '{dtype}', 'fortran_order': False, 'shape': {shape}, }}"
    text += " " * (63 - (len(text) + 10) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text)) + text.encode()


def _map_commands(bad: Path, good: Path) -> list[list[str]]:
    """Every command that reads a map, with `bad` in each place a map goes."""
    out = bad.parent / "out"
    return [
        ["localize", str(good), str(bad)],
        ["localize", str(bad), str(good), "--format", "json"],
        ["view", str(bad), "-o", str(out) + ".png"],
        ["crop", str(bad), "--center", "0", "0", "0", "--radius", "5", "-o", str(out) + ".json"],
        ["align", str(good), str(bad), "-o", str(out) + ".json", "--g2o", str(out) + ".g2o"],
        ["update-map", str(good), str(bad), "-o", str(out) + ".json"],
    ]


def map_case(name: str, make: Callable[[Path], Path]) -> list[Case]:
    """One case per map-reading command for the bad map file `make(folder)` writes."""

    def setup_for(index: int) -> Callable[[Path], tuple[list[str], list[str]]]:
        def setup(folder: Path) -> tuple[list[str], list[str]]:
            good = _write(folder / "good.json", valid_map())
            bad = make(folder)
            return _map_commands(bad, good)[index], [bad.name]

        return setup

    return [Case(f"{name}-{i}", setup_for(i)) for i in range(6)]


def _doc(change: Callable[[dict], None]) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        document = valid_map()
        change(document)
        return _write(folder / "bad.json", document)

    return make


def _text(text: str, name: str = "bad.json") -> Callable[[Path], Path]:
    return lambda folder: _write(folder / name, text)


def _set(key: str, value, index: int = 0) -> Callable[[dict], None]:
    def change(document: dict) -> None:
        document["objects"][index][key] = value

    return change


def _points_file(make_npz: Callable[[Path], None], name: str = "p.npz") -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        document = valid_map()
        for obj in document["objects"]:
            obj.pop("points")
        document["points_file"] = name
        make_npz(folder)
        return _write(folder / "bad.json", document)

    return make


def _npz_with(members: dict[str, bytes]) -> Callable[[Path], None]:
    def make(folder: Path) -> None:
        with zipfile.ZipFile(folder / "p.npz", "w", zipfile.ZIP_DEFLATED) as archive:
            for member, data in members.items():
                archive.writestr(member, data)

    return make


def _fifo(folder: Path) -> None:
    os.mkfifo(folder / "p.npz")


def _escape_link(folder: Path) -> None:
    outside = folder.parent / f"{folder.name}-outside.npz"
    np.savez(outside, o0=np.zeros((3, 3)))
    (folder / "p.npz").symlink_to(outside)


def _huge_zeros_member(folder: Path) -> None:
    """A small .npz whose unreferenced member declares 200M x 3 doubles (4.8 GB) of zeros:
    the data is a stream of deflated zeros, cheap to write, enormous to decompress."""
    with zipfile.ZipFile(folder / "p.npz", "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("o0.npy", _npy(np.zeros((3, 3))))
        with archive.open("unused.npy", "w", force_zip64=True) as member:
            member.write(npy_header((200_000_000, 3)))
            chunk = bytes(2**24)
            for _ in range(1):  # 16 MB of zeros written; the header claims 4.8 GB
                member.write(chunk)


def _npy(array: np.ndarray) -> bytes:
    import io

    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=False)
    return buffer.getvalue()


@functools.cache
def _many_objects_text(count: int) -> str:
    objects = ",".join(
        f'{{"id":"o{i}","label":"chair","position":[{i % 300},{i // 300},0]}}' for i in range(count)
    )
    return '{"format":"semloc-map","version":1,"objects":[' + objects + "]}"


def _many_objects(count: int) -> Callable[[Path], Path]:
    return lambda folder: _write(folder / "bad.json", _many_objects_text(count))


MAP_CASES: list[Case] = [
    *map_case("deep-nesting", _text("[" * 100_000)),
    *map_case(
        "deep-in-objects", _text('{"format":"semloc-map","version":1,"objects":' + "[" * 50_000)
    ),
    *map_case("huge-int", _text(json.dumps(valid_map()).replace("0.4]", "1" + "0" * 400 + "]", 1))),
    *map_case("seen-1e30", _doc(_set("seen", 10**30))),
    *map_case("score-1e30", _doc(_set("score", 10**30))),
    *map_case("point-1e300", _doc(_set("points", [[0, 0, 1e300]] * 5))),
    *map_case("size-1e308", _doc(_set("size", [1e308, 1e308, 1e308]))),
    *map_case("position-1e308", _doc(_set("position", [1e308, -1e308, 0]))),
    *map_case("up-1e308", _doc(lambda d: d.update(up=[0, 1e308, 1e308]))),
    *map_case(
        "npy-not-npz", _points_file(lambda f: np.save(f / "p.npy", np.zeros((3, 3))), "p.npy")
    ),
    *map_case("npz-header-1e12", _points_file(_npz_with({"o0.npy": npy_header((10**12, 3))}))),
    *map_case("npz-unreferenced-huge", _points_file(_huge_zeros_member)),
    *map_case("npz-fifo", _points_file(_fifo)),
    *map_case("npz-absolute", _points_file(lambda f: None, "/etc/passwd")),
    *map_case("npz-dotdot", _points_file(lambda f: None, "../../../../etc/passwd.npz")),
    *map_case("npz-symlink-escape", _points_file(_escape_link)),
    *map_case("markup-id", _doc(_set("id", "[/x0]"))),
    *map_case("mathtext-label", _doc(_set("label", "$\\undefinedcommand{$"))),
    *map_case("surrogate-label", _text(json.dumps(valid_map()).replace('"chair"', '"\\ud800"', 1))),
    *map_case("label-50k", _doc(_set("label", "x" * 50_000))),
    *map_case("objects-100001", _many_objects(100_001)),
    *map_case("string-numbers", _doc(_set("position", ["1", "2", "3"]))),
    *map_case("bool-coordinates", _doc(_set("position", [True, 0, 0]))),
    *map_case("version-true", _doc(lambda d: d.update(version=True))),
    *map_case("negative-seen", _doc(_set("seen", -1))),
    *map_case(
        "duplicate-key",
        _text(json.dumps(valid_map()).replace('"name": "fuzz"', '"name": "a", "name": "b"')),
    ),
    *map_case("not-utf8", lambda f: _write(f / "bad.json", b'{"format": "\xff\xfe"}')),
    *map_case("empty", _text("")),
    *map_case("binary", lambda f: _write(f / "bad.json", bytes(range(256)) * 4)),
    *map_case("missing", lambda f: f / "bad.json"),
    *map_case("folder", lambda f: (f / "bad.json").mkdir() or f / "bad.json"),
]


def _crop(map_file: Path, center: str, radius: str, out: Path | str) -> list[str]:
    """`semloc crop` arguments with a centre given as "x y z"."""
    return ["crop", str(map_file), "--center", *center.split(), "--radius", radius, "-o", str(out)]


def _option_case(name: str, argv: Callable[[Path, Path], list[str]], blame: list[str]) -> Case:
    def setup(folder: Path) -> tuple[list[str], list[str]]:
        good = _write(folder / "good.json", valid_map())
        return argv(folder, good), blame

    return Case(name, setup)


OPTION_CASES: list[Case] = [
    _option_case(
        "localize-gamma-nan",
        lambda f, g: ["localize", str(g), str(g), "--gamma", "nan"],
        ["--gamma"],
    ),
    _option_case(
        "localize-out-dev-full",
        lambda f, g: ["localize", str(g), str(g), "-o", "/dev/full"],
        ["/dev/full"],
    ),
    _option_case(
        "localize-out-folder",
        lambda f, g: ["localize", str(g), str(g), "-o", str(f)],
        [f"{os.sep}"],
    ),
    _option_case(
        "crop-radius-nan",
        lambda f, g: _crop(g, "0 0 0", "nan", f / "c.json"),
        ["--radius"],
    ),
    _option_case(
        "crop-center-inf",
        lambda f, g: _crop(g, "inf 0 0", "3", f / "c.json"),
        ["--center"],
    ),
    _option_case(
        "view-missing-folder",
        lambda f, g: ["view", str(g), "-o", str(f / "no" / "dir" / "x.png")],
        ["x.png"],
    ),
    _option_case(
        "view-mathtext-title",
        lambda f, g: ["view", str(g), "--title", "$\\undefinedcommand{$", "-o", str(f / "v.png")],
        [],
    ),
    _option_case(
        "view-surrogate-title",
        lambda f, g: ["view", str(g), "--title", "a\udcff[/x]", "-o", str(f / "v[/x].png")],
        [],
    ),
    _option_case(
        "localize-config-deep-nesting",
        lambda f, g: [
            "localize",
            str(g),
            str(g),
            "--config",
            str(_write(f / "s.json", "[" * 10**5)),
        ],
        ["s.json"],
    ),
    _option_case(
        "view-result-deep-nesting",
        lambda f, g: [
            "view",
            str(g),
            "--result",
            str(_write(f / "r.json", "[" * 10**5)),
            "-o",
            str(f / "v.png"),
        ],
        ["r.json"],
    ),
    _option_case(
        "view-out-dev-full", lambda f, g: ["view", str(g), "-o", "/dev/full"], ["/dev/full"]
    ),
    _option_case(
        "export-out-dev-full", lambda f, g: ["export", str(g), "-o", "/dev/full"], ["/dev/full"]
    ),
    _option_case(
        "crop-out-dev-full",
        lambda f, g: _crop(g, "0 0 0", "5", "/dev/full"),
        ["/dev/full"],
    ),
    _option_case(
        "simulate-drift-nan", lambda f, g: ["simulate", str(f / "s"), "--drift", "nan"], ["--drift"]
    ),
    _option_case(
        "demo-gamma-nan",
        lambda f, g: ["demo", "--out", str(f / "d"), "--gamma", "nan"],
        ["--gamma"],
    ),
]


# Importers: the format fixtures and a mutation corpus over them ------------------------------
def _scannet(folder: Path) -> tuple[Path, list[str]]:
    write_scannet(folder / "scene")
    return folder / "scene", []


def _scan2cad(folder: Path) -> tuple[Path, list[str]]:
    return write_scan2cad(folder), []


def _replica(folder: Path) -> tuple[Path, list[str]]:
    return write_replica(folder / "replica"), []


def _rscan(folder: Path) -> tuple[Path, list[str]]:
    return write_rscan(folder / "rscan"), []


SCENES = {"scannet": _scannet, "scan2cad": _scan2cad, "replica": _replica, "3rscan": _rscan}

HOSTILE_VALUES = [None, True, "x", -1, 0, 1e308, -1e308, [], {}, [1, 2], "[/x0]", 2**70,
                  [[[[[]]]]], "", 3.5]  # fmt: skip


def _leaves(value, path=()):
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _leaves(item, (*path, key))
    elif isinstance(value, list) and value and len(value) <= 64:
        for i, item in enumerate(value):
            yield from _leaves(item, (*path, i))
    yield path


def mutate_json(text: str, rng: random.Random) -> str:
    """Replace a random node of the JSON document by a hostile value (or the text by garbage)."""
    document = json.loads(text)
    paths = list(_leaves(document))
    path = rng.choice(paths)
    value = rng.choice(HOSTILE_VALUES)
    if not path:
        return json.dumps(value)
    node = document
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return json.dumps(document)


def mutate_bytes(data: bytes, rng: random.Random) -> bytes:
    """Truncate, flip bytes, or edit a header count of binary / text data."""
    choice = rng.randrange(4)
    if choice == 0:
        return data[: rng.randrange(len(data))]
    if choice == 1:
        damaged = bytearray(data)
        for _ in range(rng.randint(1, 8)):
            damaged[rng.randrange(min(len(damaged), 400))] = rng.randrange(256)
        return bytes(damaged)
    if choice == 2 and b"element vertex " in data[:400]:
        count = rng.choice([b"-5", b"99999999999999", b"0", b"1e3", b"3"])
        head, _, tail = data.partition(b"element vertex ")
        return head + b"element vertex " + count + tail[tail.index(b"\n") :]
    cut = rng.randrange(len(data))
    return (
        data[:cut]
        + rng.choice([b"nan", b"-1", b"\xff\xfe", b"1e400", b"f -3 -2 -1\n"])
        + data[cut:]
    )


def mutated_scene(kind: str, seed: int) -> Case:
    """The `kind` fixture with one of its files damaged (chosen and damaged from `seed`)."""

    def setup(folder: Path) -> tuple[list[str], list[str]]:
        source, extra = SCENES[kind](folder)
        rng = random.Random(f"{kind}-{seed}")
        files = sorted(p for p in folder.rglob("*") if p.is_file())
        target = rng.choice(files)
        data = target.read_bytes()
        if target.suffix == ".json":
            target.write_text(mutate_json(data.decode(), rng))
        else:
            target.write_bytes(mutate_bytes(data, rng))
        argv = ["convert", kind, str(source), "-o", str(folder / "out.json"), *extra]
        blame = [str(folder), "--"]
        return argv, blame

    return Case(f"convert-{kind}-mutated-{seed}", setup)


def _convert_case(name: str, kind: str, options: Callable[[Path], list[str]], blame) -> Case:
    def setup(folder: Path) -> tuple[list[str], list[str]]:
        source, _ = SCENES[kind](folder)
        return [
            "convert",
            kind,
            str(source),
            "-o",
            str(folder / "out.json"),
            *options(folder),
        ], blame

    return Case(name, setup)


CONVERT_CASES: list[Case] = [
    _convert_case("convert-voxel-nan", "scannet", lambda f: ["--voxel", "nan"], ["--voxel"]),
    _convert_case(
        "convert-scan-output-folder",
        "scan2cad",
        lambda f: ["--scan-output", str(f)],
        ["--scan-output"],
    ),
    _convert_case(
        "convert-scan-output-same",
        "scan2cad",
        lambda f: ["--scan-output", str(f / "out.json")],
        ["--scan-output"],
    ),
    _convert_case(
        "convert-label-map-not-utf8",
        "scannet",
        lambda f: ["--label-map", str(_write(f / "lm.tsv", b"\xff\xfe\x00raw"))],
        ["lm.tsv"],
    ),
    _convert_case(
        "convert-label-map-fifo",
        "scannet",
        lambda f: ["--label-map", str(os.mkfifo(f / "lm.json") or f / "lm.json")],
        ["lm.json"],
    ),
    Case(
        "convert-replica-gravity-1e308",
        lambda f: (
            [
                "convert",
                "replica",
                str(write_replica(f / "replica", gravity=(1e308, 1e308, 0.0))),
                "-o",
                str(f / "out.json"),
            ],
            ["gravity_dir"],
        ),
    ),
]


def _scan2cad_negative_bbox(folder: Path) -> tuple[list[str], list[str]]:
    path = write_scan2cad(folder)
    document = json.loads(path.read_text())
    document[0]["aligned_models"][0]["bbox"] = [-1, 0.5, 0.5]
    path.write_text(json.dumps(document))
    return ["convert", "scan2cad", str(path), "-o", str(folder / "out.json")], [path.name]


def _rscan_string_column(folder: Path) -> tuple[list[str], list[str]]:
    path = write_rscan(folder / "rscan")
    data = np.load(path)
    dtype = [(n, "U8" if n == "x" else data.dtype[n]) for n in data.dtype.names]
    text = np.zeros(len(data), dtype=dtype)
    for name in data.dtype.names:
        text[name] = data[name].astype(str) if name == "x" else data[name]
    np.save(path, text)
    return ["convert", "3rscan", str(path), "-o", str(folder / "out.json")], [path.name]


def _scannet_deep_aggregation(folder: Path) -> tuple[list[str], list[str]]:
    write_scannet(folder / "scene")
    _write(folder / "scene" / "scene0001_00.aggregation.json", "[" * 100_000)
    argv = ["convert", "scannet", str(folder / "scene"), "-o", str(folder / "out.json")]
    return argv, ["scene0001_00.aggregation.json"]


CONVERT_CASES += [
    Case("convert-scan2cad-negative-bbox", _scan2cad_negative_bbox),
    Case("convert-3rscan-string-column", _rscan_string_column),
    Case("convert-scannet-deep-aggregation", _scannet_deep_aggregation),
    Case(
        "convert-out-dev-full",
        lambda f: (["convert", "scannet", str(_scannet(f)[0]), "-o", "/dev/full"], ["/dev/full"]),
    ),
    _convert_case(
        "convert-scan-output-dev-full",
        "scan2cad",
        lambda f: ["--scan-output", "/dev/full"],
        ["/dev/full"],
    ),
]

MUTATED_CASES: list[Case] = [mutated_scene(kind, seed) for kind in SCENES for seed in range(12)]
