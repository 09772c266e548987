"""``visloc render localize`` and ``visloc localize`` through ``main([...])``."""

import csv

import numpy as np
import pytest

from visloc.cli import main


def test_localize_a_rendered_flight(tmp_path, capsys):
    src = tmp_path / "flight"  # outputs may not go into the input folder
    assert main(["render", "localize", str(src), "--seconds", "0.5", "--fps", "30", "--seed", "2"]) == 0
    out = tmp_path / "est.csv"
    code = main(["localize", str(src), "--camera", str(src / "camera.yml"), "--map", str(src / "map.yml"),
                 "--dict", "DICT_4X4_100", "--fps", "30", "--truth", str(src / "ground_truth.csv"),
                 "--out", str(out), "--rerun", str(tmp_path / "l.rrd")])
    assert code == 0
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    gt = np.genfromtxt(src / "ground_truth.csv", delimiter=",", names=True)
    assert len(rows) == len(gt) and all(r["fix"] == "used" for r in rows)
    err = np.array([float(r["error_m"]) for r in rows])
    assert np.median(err) < 0.002  # 2 mm
    v = np.array([[float(r["vx"]), float(r["vy"])] for r in rows[5:]])
    true_v = np.stack([gt["vx"][5:], gt["vy"][5:]], axis=1)
    assert np.median(np.linalg.norm(v - true_v, axis=1)) < 0.05
    assert "median position error" in capsys.readouterr().err
    assert (tmp_path / "l.rrd").stat().st_size > 0


def test_localize_following_the_markers_between_full_searches(tmp_path):
    # --redetect-every 5: the fixes of the full search on every frame, within a twentieth of their
    # error from the truth (the map's markers in the last fix's view are followed too)
    src = tmp_path / "flight"
    assert main(["render", "localize", str(src), "--seconds", "0.5", "--fps", "30", "--seed", "3"]) == 0
    rows = {}
    for every in ("1", "5"):
        out = tmp_path / f"est{every}.csv"
        assert main(["localize", str(src), "--camera", str(src / "camera.yml"), "--map", str(src / "map.yml"),
                     "--dict", "DICT_4X4_100", "--fps", "30", "--out", str(out), "--redetect-every", every,
                     "--truth", str(src / "ground_truth.csv"), "--quiet"]) == 0
        with open(out, newline="") as fh:
            rows[every] = list(csv.DictReader(fh))
    full, followed = rows["1"], rows["5"]
    assert len(full) == len(followed) == 15 and all(r["fix"] == "used" for r in full + followed)
    xyz = [[[float(r[k]) for k in ("x", "y", "z")] for r in rs] for rs in (full, followed)]
    assert np.abs(np.array(xyz[0]) - np.array(xyz[1])).max() < 1e-4
    assert all(np.median([float(r["error_m"]) for r in rs]) < 0.002 for rs in (full, followed))
    with pytest.raises(SystemExit) as stop:  # argparse's own check
        main(["localize", str(src), "--camera", str(src / "camera.yml"), "--map", str(src / "map.yml"),
              "--fps", "30", "--redetect-every", "0"])
    assert stop.value.code == 2


def test_localize_needs_fps_for_folders_and_a_valid_map(tmp_path, capsys):
    assert main(["render", "localize", str(tmp_path), "--seconds", "0.1", "--fps", "30"]) == 0
    code = main(["localize", str(tmp_path), "--camera", str(tmp_path / "camera.yml"), "--map", str(tmp_path / "map.yml")])
    assert code == 2 and "--fps" in capsys.readouterr().err
    (tmp_path / "bad.yml").write_text("%YAML:1.0\nmarkers: 3\n")
    code = main(["localize", str(tmp_path), "--camera", str(tmp_path / "camera.yml"), "--map", str(tmp_path / "bad.yml"),
                 "--fps", "30"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "markers" in err


def test_imu_as_control_input_lowers_the_velocity_error(tmp_path):
    src = tmp_path / "flight"
    assert main(["render", "localize", str(src), "--seconds", "1.5", "--fps", "30", "--seed", "5"]) == 0
    gt = np.genfromtxt(src / "ground_truth.csv", delimiter=",", names=True)
    true_v = np.stack([gt["vx"], gt["vy"], gt["vz"]], axis=1)

    def velocity_rms(extra):
        out = tmp_path / "est.csv"
        assert main(["localize", str(src), "--camera", str(src / "camera.yml"), "--map",
                     str(src / "map.yml"), "--dict", "DICT_4X4_100", "--fps", "30", "--out", str(out),
                     "--quiet", *extra]) == 0
        with open(out, newline="") as fh:
            rows = list(csv.DictReader(fh))
        v = np.array([[float(r[k]) for k in ("vx", "vy", "vz")] for r in rows])
        p = np.array([[float(r[k]) for k in ("x", "y", "z")] for r in rows])
        return float(np.sqrt(np.mean(np.sum((v - true_v)[10:] ** 2, axis=1)))), p

    plain, _ = velocity_rms([])
    fused, _ = velocity_rms(["--imu", str(src / "imu.csv")])
    assert fused < 0.8 * plain, (fused, plain)


def test_a_camera_file_for_another_size_is_scaled_with_one_warning(tmp_path, capsys):
    from visloc.pose import Camera
    from visloc.synth import write_camera_yml

    src = tmp_path / "flight"
    assert main(["render", "localize", str(src), "--seconds", "0.2", "--fps", "30", "--seed", "3"]) == 0
    cam = Camera.from_file(src / "camera.yml")
    w, h = cam.size
    big = cam.scaled(2 * w, 2 * h)
    write_camera_yml(tmp_path / "big.yml", big.K, (2 * w, 2 * h))
    capsys.readouterr()
    out = tmp_path / "est.csv"
    assert main(["localize", str(src), "--camera", str(tmp_path / "big.yml"), "--map", str(src / "map.yml"),
                 "--dict", "DICT_4X4_100", "--fps", "30", "--out", str(out), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert err.count("scaling it") == 1 and f"{2 * w}x{2 * h}" in err
    with open(out, newline="") as fh:
        assert all(r["fix"] == "used" for r in csv.DictReader(fh))  # the scaled camera is the right one


def test_localize_reads_the_maps_dictionary_and_refuses_another(tmp_path, capsys):
    src = tmp_path / "flight"
    assert main(["render", "localize", str(src), "--seconds", "0.2", "--fps", "30", "--seed", "4"]) == 0
    base = ["localize", str(src), "--camera", str(src / "camera.yml"), "--map", str(src / "map.yml"), "--fps", "30",
            "--quiet"]
    out = tmp_path / "est.csv"
    assert main([*base, "--out", str(out)]) == 0  # no --dict: the map's DICT_4X4_100
    with open(out, newline="") as fh:
        assert all(r["fix"] == "used" for r in csv.DictReader(fh))
    capsys.readouterr()
    assert main([*base, "--dict", "DICT_4X4_50"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "DICT_4X4_100" in err


def test_imu_rows_skipped_or_out_of_time_are_said(tmp_path, capsys):
    src = tmp_path / "flight"
    assert main(["render", "localize", str(src), "--seconds", "0.3", "--fps", "30", "--seed", "6"]) == 0
    lines = (src / "imu.csv").read_text().splitlines()
    bad = tmp_path / "imu_bad.csv"
    bad.write_text("\n".join([lines[0], lines[1], "0.0021,x,0,0,nan,0,9.8", *lines[3:]]) + "\n")
    late = tmp_path / "imu_late.csv"
    late.write_text("\n".join([lines[0]] + [",".join([str(100 + float(r.split(",")[0]))] + r.split(",")[1:])
                                            for r in lines[1:]]) + "\n")
    base = ["localize", str(src), "--camera", str(src / "camera.yml"), "--map", str(src / "map.yml"), "--fps", "30",
            "--quiet"]
    capsys.readouterr()
    assert main([*base, "--imu", str(bad)]) == 0
    assert "1 rows without finite numbers skipped (lines 3)" in capsys.readouterr().err
    assert main([*base, "--imu", str(late)]) == 0
    assert "do not overlap" in capsys.readouterr().err


def test_an_output_over_the_truth_file_is_refused(tmp_path, capsys):
    src = tmp_path / "flight"
    assert main(["render", "localize", str(src), "--seconds", "0.1", "--fps", "30"]) == 0
    truth = tmp_path / "truth.csv"
    truth.write_bytes((src / "ground_truth.csv").read_bytes())
    before = truth.read_bytes()
    code = main(["localize", str(src), "--camera", str(src / "camera.yml"), "--map", str(src / "map.yml"), "--fps", "30",
                 "--truth", str(truth), "--out", str(truth)])
    assert code == 2 and "overwritten" in capsys.readouterr().err and truth.read_bytes() == before


def test_frames_before_the_first_fix_and_outside_the_truth_have_no_position_or_error(tmp_path, capsys):
    # before the first fix the rows held the prior (0, 0, 0) and counted in the median error;
    # a truth file that did not cover a frame's time was clamped to its nearest row
    import cv2

    src = tmp_path / "flight"
    assert main(["render", "localize", str(src), "--seconds", "0.3", "--fps", "30", "--seed", "4"]) == 0
    frames = sorted(src.glob("*.png"))
    for p in frames[:4]:  # the first four frames see nothing
        cv2.imwrite(str(p), np.zeros_like(cv2.imread(str(p))))
    gt = (src / "ground_truth.csv").read_text().splitlines()
    short = tmp_path / "truth.csv"
    short.write_text("\n".join(gt[:7]) + "\n")  # covers frames 0-5 only
    out = tmp_path / "est.csv"
    args = ["localize", str(src), "--camera", str(src / "camera.yml"), "--map", str(src / "map.yml"), "--fps", "30"]
    assert main([*args, "--truth", str(short), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["fix"] for r in rows[:5]] == ["none"] * 4 + ["used"]
    assert all(r["x"] == r["vx"] == r["std_x"] == r["error_m"] == "" for r in rows[:4])
    assert all(r["x"] != "" for r in rows[4:])
    assert [r["error_m"] != "" for r in rows] == [False] * 4 + [True] * 2 + [False] * (len(rows) - 6)
    assert "leave out 3 frame(s)" in err and "median position error" in err
    black = tmp_path / "black"
    black.mkdir()
    for p in frames[:3]:
        cv2.imwrite(str(black / p.name), np.zeros((240, 320), np.uint8))
    assert main(["localize", str(black), *args[2:], "--out", str(tmp_path / "b.csv")]) == 0
    assert "no frame gave a position fix" in capsys.readouterr().err


def test_a_map_id_its_dictionary_lacks_is_a_usage_error(tmp_path, capsys):
    # localize used to accept it (and find nothing) while render map refused it
    from visloc.pose import Camera, MarkerMap

    square = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.1, -0.1, 0.0], [0.0, -0.1, 0.0]])
    Camera(np.array([[300.0, 0.0, 160.0], [0.0, 300.0, 120.0], [0.0, 0.0, 1.0]]), size=(320, 240)).to_file(
        tmp_path / "cam.yml")
    frames = tmp_path / "frames"
    frames.mkdir()
    (frames / "f.png").write_bytes((tmp_path / "cam.yml").read_bytes())  # never read: the map is refused first
    for ids in ([99], [-1], [3, 50]):
        MarkerMap({i: square + (0.2 * k, 0.0, 0.0) for k, i in enumerate(ids)}, "DICT_4X4_50").to_file(tmp_path / "m.yml")
        for argv in (["localize", str(frames), "--fps", "30", "--camera", str(tmp_path / "cam.yml")],
                     ["render", "map"]):
            code = main([*argv, "--map", str(tmp_path / "m.yml")] if argv[0] == "localize"
                        else [*argv, str(tmp_path / "m.yml"), str(tmp_path / "s.png")])
            bad = [i for i in ids if not 0 <= i < 50]
            assert code == 2 and f"map ids {bad} are not in dictionary DICT_4X4_50 (ids 0 to 49)" in capsys.readouterr().err
