"""The reliability corpus (issue 14): hostile and odd inputs made here, run through every
command. Each case asserts its exit status, no traceback, a one-line ``visloc <command>: ...``
message when it fails, every input file unchanged (hashed before and after) and its outputs
complete and parseable."""

import csv
import hashlib
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from visloc.cli import main


def _video(path: Path, frames: list[np.ndarray], corrupt: bool) -> None:
    h, w = frames[0].shape[:2]
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (w, h))
    for f in frames:
        vw.write(cv2.cvtColor(f, cv2.COLOR_GRAY2BGR) if f.ndim == 2 else f)
    vw.release()
    if corrupt:  # bytes overwritten in the middle of the stream
        data = bytearray(path.read_bytes())
        mid = len(data) // 2
        data[mid : mid + 2000] = bytes(2000)
        path.write_bytes(bytes(data))


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    """Good renders and the hostile files, in one folder (its inputs are hashed by each case)."""
    root = tmp_path_factory.mktemp("corpus")
    good, flow = root / "good", root / "flow"
    assert main(["render", "localize", str(good), "--seconds", "0.2", "--fps", "15", "--seed", "1"]) == 0
    assert main(["render", "flow", str(flow), "--seconds", "0.1", "--fps", "30", "--seed", "2"]) == 0
    frames = sorted(good.glob("frame_*.png"))
    png = frames[0].read_bytes()
    img = cv2.imread(str(frames[0]), cv2.IMREAD_GRAYSCALE)
    (root / "empty.png").write_bytes(b"")
    (root / "text.png").write_text("not an image\n")
    (root / "trunc.png").write_bytes(png[: len(png) // 2])
    cv2.imwrite(str(root / "tiny.png"), np.full((1, 1), 128, np.uint8))
    cv2.imwrite(str(root / "deep12.png"), img.astype(np.uint16) * 16)  # 12-bit data in a 16-bit PNG
    mixed = root / "mixed"
    mixed.mkdir()
    for k, src in enumerate([frames[0], root / "text.png", root / "tiny.png", root / "trunc.png", frames[1]]):
        (mixed / f"f{k}.png").write_bytes(src.read_bytes())
    _video(root / "corrupt.avi", [cv2.imread(str(f)) for f in frames] * 4, corrupt=True)
    (root / "garbage.yml").write_bytes(bytes(np.random.default_rng(0).integers(0, 256, 300, np.uint8)))
    (root / "empty.yml").write_text("")
    (root / "garbage.bag").write_bytes(bytes(np.random.default_rng(1).integers(0, 256, 500, np.uint8)))
    (root / "dict99.yml").write_text("%YAML:1.0\n---\nnmarkers: 2\nmarkersize: 4\nmaxCorrectionBits: 99\n"
                                     "marker_0: \"1010010110100101\"\nmarker_1: \"0110100101101001\"\n")
    heights = (flow / "heights.csv").read_text().splitlines()
    (root / "heights_bad.csv").write_text("\n".join([heights[0], heights[1], "1,abc,zz"]) + "\n")
    imu = (good / "imu.csv").read_text().splitlines()
    (root / "imu_bad.csv").write_text("\n".join([imu[0], *imu[1:4], ",".join(["nan"] * len(imu[0].split(","))),
                                                 "text,row", *imu[4:]]) + "\n")
    (root / "board.yml").write_text("%YAML:1.0\n---\nboard_type: charuco\nsquares_x: 5\nsquares_y: 4\n"
                                    "square_length: 0.03\nmarker_length: 0.022\ndictionary: DICT_5X5_100\n")
    return root


def _hashes(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def _jsonl(path: Path) -> list[dict]:
    return [json.loads(x) for x in path.read_text().splitlines()]


def _csv(path: Path) -> list[dict]:
    with path.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert rows and all(None not in r for r in rows)  # every row has the header's columns
    return rows


# (command line with {c} = the corpus and {o} = a fresh output folder, allowed exit statuses,
#  outputs that must then exist and parse, the words the last message line must hold)
CASES = {
    "detect-mixed-folder": ("detect {c}/mixed --out {o}/d.jsonl", {1}, ["{o}/d.jsonl"], "frame"),
    "detect-empty-file": ("detect {c}/empty.png --out {o}/d.jsonl", {1, 2}, [], "empty.png"),
    "detect-truncated-png": ("detect {c}/trunc.png", {1, 2}, [], "trunc.png"),
    "detect-one-pixel": ("detect {c}/tiny.png", {1, 2}, [], "tiny.png"),
    "detect-12-bit": ("detect {c}/deep12.png --dict DICT_4X4_100 --out {o}/d.jsonl", {0}, ["{o}/d.jsonl"], ""),
    "detect-garbage-dict": ("detect {c}/good --dict {c}/garbage.yml", {2}, [], "garbage.yml"),
    "detect-empty-dict": ("detect {c}/good --dict {c}/empty.yml", {2}, [], "empty.yml"),
    "detect-correction-99": ("detect {c}/good --dict {c}/dict99.yml", {2}, [], "maxCorrectionBits"),
    "detect-garbage-camera": ("detect {c}/good --camera {c}/garbage.yml --marker-length 0.1", {2}, [], "garbage.yml"),
    "detect-corrupt-video": ("detect {c}/corrupt.avi --dict DICT_4X4_100 --out {o}/d.jsonl", {0, 1},
                             ["{o}/d.jsonl"], ""),
    "detect-out-is-input": ("detect {c}/good/frame_00000.png --out {c}/good/frame_00000.png", {2}, [], "input"),
    "detect-annotate-into-input": ("detect {c}/good --annotate {c}/good", {2}, [], "input"),
    "flow-heights-missing": (("flow {c}/flow --fps 30 --camera {c}/flow/camera.yml --height-csv {c}/heights_bad.csv "
                             "--out {o}/f.csv"), {1}, ["{o}/f.csv"], ""),
    "flow-empty-camera": ("flow {c}/flow --camera {c}/empty.yml --height 1", {2}, [], "empty.yml"),
    "flow-negative-height": ("flow {c}/flow --camera {c}/flow/camera.yml --height -1", {2}, [], "height"),
    "flow-out-is-input": (("flow {c}/flow --camera {c}/flow/camera.yml --height-csv {c}/flow/heights.csv "
                          "--out {c}/flow/heights.csv"), {2}, [], "input"),
    "localize-garbage-map": ("localize {c}/good --camera {c}/good/camera.yml --map {c}/garbage.yml", {2}, [],
                             "garbage.yml"),
    "localize-bad-imu-rows": (("localize {c}/good --fps 15 --camera {c}/good/camera.yml --map {c}/good/map.yml "
                              "--imu {c}/imu_bad.csv --out {o}/l.csv"), {0, 1}, ["{o}/l.csv"], ""),
    "localize-mixed-folder": (("localize {c}/mixed --fps 15 --camera {c}/good/camera.yml --map {c}/good/map.yml "
                              "--out {o}/l.csv"), {1}, ["{o}/l.csv"], ""),
    "track-garbage-body": (("track {c}/good --camera {c}/good/camera.yml --body {c}/garbage.yml "
                           "--reference {c}/good/map.yml"), {2}, [], "garbage.yml"),
    "calibrate-garbage-board": ("calibrate {c}/good --board {c}/garbage.yml --out {o}/cam.yml", {2}, [],
                                "garbage.yml"),
    "calibrate-no-board-seen": ("calibrate {c}/mixed --board {c}/board.yml --out {o}/cam.yml", {1, 2}, [], ""),
    "render-map-no-extension": ("render map {c}/good/map.yml {o}/sheet", {2}, [], ".png"),
    "render-map-huge-dpi": ("render map {c}/good/map.yml {o}/sheet.png --dpi 1e6", {2}, [], "dpi"),
    "render-localize-huge": ("render localize {o}/r --seconds 1e9", {2}, [], "seconds"),
    "render-board-garbage": ("render board {c}/garbage.yml {o}/b.png", {2}, [], "garbage.yml"),
    "render-markers-zero-size": ("render markers {o}/r --size 0x0", {2}, [], "size"),
    "model": ("model --json", {0}, [], ""),
    "info-folder": ("info {c}/good --json", {0}, [], ""),
    "info-garbage-bag": ("info {c}/garbage.bag", {2}, [], "garbage.bag"),
    "detect-garbage-bag": ("detect {c}/garbage.bag", {2}, [], "garbage.bag"),
    "detect-topic-for-a-folder": ("detect {c}/good --topic /camera/image", {2}, [], "topic"),
    "robust-nan-sigma": ("robust --sigma nan", {2}, [], "sigma"),
    "sim-huge": ("sim hover --seconds 1e8", {2}, [], "seconds"),
    "sim-plot-under-a-file": ("sim hover --seconds 0.5 --plot {c}/good/map.yml/p.png", {2}, [], "plot"),
    "demo-out-is-a-file": ("demo --out {c}/good/map.yml", {2}, [], "map.yml"),
}


# every frame has its row, and every frame skipped its warning line: (rows, skipped)
ROWS = {"detect-mixed-folder": (5, 3), "localize-mixed-folder": (5, 3), "flow-heights-missing": (3, 2)}


@pytest.mark.parametrize("case", list(CASES))
def test_corpus_case(case, corpus, tmp_path, capsys):
    line, codes, outputs, words = CASES[case]
    argv = line.format(c=corpus, o=tmp_path).split()
    before = _hashes(corpus)
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own usage errors (status 2, its message last)
        code = exc.code
    err = capsys.readouterr().err
    assert code in codes, f"{case}: exit {code}\n{err}"
    assert "Traceback" not in err and "internal error" not in err, err
    assert _hashes(corpus) == before, f"{case}: an input file changed"
    if code:
        last = [x for x in err.splitlines() if x.strip()][-1]
        assert last.startswith(f"visloc {argv[0]}"), err
        assert words.lower() in last.lower() or any(words.lower() in x.lower() for x in err.splitlines()), err
    for out in outputs:
        path = Path(out.format(o=tmp_path))
        rows = _jsonl(path) if path.suffix == ".jsonl" else _csv(path)
        assert rows, f"{case}: {path.name} is empty"
        if case in ROWS:
            n, skipped = ROWS[case]
            assert len(rows) == n
            assert sum("warning" in x for x in err.splitlines()) >= skipped, err
