"""``visloc render flow`` and ``visloc flow`` through ``main([...])``."""

import csv

import numpy as np
import pytest

from visloc.cli import main


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    out = tmp_path_factory.mktemp("flight")
    assert main(["render", "flow", str(out), "--seconds", "0.25", "--fps", "60", "--seed", "4"]) == 0
    return out


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _truth(folder):
    return np.genfromtxt(folder / "ground_truth.csv", delimiter=",", names=True)


def test_flow_on_frames_matches_the_ground_truth(flight, tmp_path, capsys):
    out = tmp_path / "v.csv"
    code = main(["flow", str(flight), "--camera", str(flight / "camera.yml"), "--height-csv",
                 str(flight / "heights.csv"), "--fps", "60", "--out", str(out), "--rerun", str(tmp_path / "f.rrd")])
    assert code == 0
    rows = _rows(out)
    gt = _truth(flight)
    assert len(rows) == len(gt) and rows[0]["reason"] == "first frame"
    v = np.array([[float(r["vx"]), float(r["vy"])] for r in rows[1:]])
    true = np.stack([gt["pair_vx"][1:], gt["pair_vy"][1:]], axis=1)
    rel = np.linalg.norm(v - true, axis=1) / np.linalg.norm(true, axis=1)
    assert np.median(rel) < 0.03
    yaw = np.array([float(r["yaw_rate"]) for r in rows[1:]])
    assert np.median(np.abs(yaw - gt["pair_yaw_rate"][1:])) < 0.05
    assert (tmp_path / "f.rrd").stat().st_size > 0
    assert "median quality" in capsys.readouterr().err


def test_flow_on_a_video(tmp_path):
    assert main(["render", "flow", str(tmp_path), "--seconds", "0.2", "--video", "--seed", "5"]) == 0
    out = tmp_path / "v.csv"
    assert main(["flow", str(tmp_path / "flight.mp4"), "--camera", str(tmp_path / "camera.yml"),
                 "--height-csv", str(tmp_path / "heights.csv"), "--out", str(out), "--quiet"]) == 0
    rows = _rows(out)
    assert len(rows) == len(_truth(tmp_path)) > 5
    assert all(float(r["quality"]) > 0.3 for r in rows[1:])


def test_unreadable_frame_is_recorded_and_skipped(flight, tmp_path, capsys):
    folder = tmp_path / "frames"
    folder.mkdir()
    for p in sorted(flight.glob("frame_*.png"))[:4]:
        (folder / p.name).write_bytes(p.read_bytes())
    (folder / "frame_00001b.png").write_bytes(b"\x89PNG broken")
    out = tmp_path / "v.csv"
    assert main(["flow", str(folder), "--camera", str(flight / "camera.yml"), "--height", "1.5",
                 "--fps", "60", "--out", str(out), "--quiet"]) == 1
    rows = _rows(out)
    assert len(rows) == 5 and rows[2]["reason"].startswith("unreadable")
    assert capsys.readouterr().err.count("warning") == 1


@pytest.mark.parametrize(
    "extra, word",
    [
        (["--height", "1.0"], "--fps"),  # image folders need a frame rate
        (["--height", "-2", "--fps", "60"], "height"),
        (["--height-csv", "{bad_csv}", "--fps", "60"], "height"),
        (["--fps", "60"], "height"),  # one of --height / --height-csv is required
    ],
)
def test_flow_configuration_errors(flight, tmp_path, capsys, extra, word):
    bad = tmp_path / "bad.csv"
    bad.write_text("frame,alt\n0,1.0\n")
    argv = ["flow", str(flight), "--camera", str(flight / "camera.yml"), *[e.format(bad_csv=bad) for e in extra]]
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and word in err


def test_a_frame_without_a_height_is_recorded_and_the_run_goes_on(flight, tmp_path, capsys):
    lines = (flight / "heights.csv").read_text().splitlines()
    (tmp_path / "heights.csv").write_text("\n".join([lines[0], *lines[1:4], *lines[5:]]) + "\n")  # no frame 3
    out = tmp_path / "v.csv"
    code = main(["flow", str(flight), "--camera", str(flight / "camera.yml"), "--height-csv",
                 str(tmp_path / "heights.csv"), "--fps", "60", "--out", str(out), "--quiet"])
    rows = _rows(out)
    assert code == 1 and len(rows) == len(_truth(flight))
    assert "no height for frame 3" in rows[3]["reason"] and float(rows[3]["quality"]) == 0
    assert rows[4]["vx"] != "" and float(rows[4]["quality"]) > 0.3  # the next frame is measured again
    assert "no height for frame 3" in capsys.readouterr().err


def test_flow_direct_is_closer_to_the_truth(flight, tmp_path):
    gt = _truth(flight)
    true = np.stack([gt["pair_vx"][1:], gt["pair_vy"][1:]], axis=1)
    errs = {}
    for extra in ([], ["--direct"]):
        out = tmp_path / f"v{len(extra)}.csv"
        assert main(["flow", str(flight), "--camera", str(flight / "camera.yml"), "--height-csv",
                     str(flight / "heights.csv"), "--fps", "60", "--out", str(out), "--quiet", *extra]) == 0
        v = np.array([[float(r["vx"]), float(r["vy"])] for r in _rows(out)[1:]])
        errs[bool(extra)] = np.median(np.linalg.norm(v - true, axis=1) / np.linalg.norm(true, axis=1))
    assert errs[True] < errs[False]


def test_pairs_without_motion_tiny_frames_and_an_imu_out_of_time_are_said(flight, tmp_path, capsys):
    # blank frames used to give a velocity of 0 (no motion was measured), 8 x 8 frames an
    # internal error, and an IMU file outside the frames' times was ignored without a word
    import cv2

    blank = tmp_path / "blank"
    blank.mkdir()
    for k in range(3):
        cv2.imwrite(str(blank / f"frame_{k:05d}.png"), np.full((240, 320), 90, np.uint8))
    cv2.imwrite(str(blank / "frame_00003.png"), np.zeros((8, 8), np.uint8))
    imu = tmp_path / "imu.csv"
    imu.write_text("t,gx,gy,gz\n" + "".join(f"{100 + k * 0.005},0.5,0.5,0\n" for k in range(20)))
    out = tmp_path / "v.csv"
    code = main(["flow", str(blank), "--camera", str(flight / "camera.yml"), "--height", "1.5", "--fps", "60",
                 "--imu", str(imu), "--out", str(out)])
    assert code == 1  # the 8 x 8 frame is recorded and skipped
    rows = _rows(out)
    assert len(rows) == 4 and "smaller than 16 x 16" in rows[3]["reason"]
    assert all(r["vx"] == r["speed"] == "" and r["quality"] == "0.0" for r in rows[1:3])
    err = capsys.readouterr().err
    assert "the IMU was not used" in err and "no motion could be measured in any of the 2" in err
    good = tmp_path / "good.csv"  # a textured flight still fills every pair's velocity
    assert main(["flow", str(flight), "--camera", str(flight / "camera.yml"), "--height", "1.5", "--fps", "60",
                 "--out", str(good), "--quiet"]) == 0
    assert all(r["vx"] != "" for r in _rows(good)[1:])
