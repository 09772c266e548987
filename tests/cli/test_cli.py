"""The command line, run through ``main([...])`` on rendered folders and videos."""

import json

import cv2
import numpy as np
import pytest

from visloc.cli import main


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("render")
    assert main(["render", "markers", str(out), "--n", "4", "--seed", "3", "--size", "320x240"]) == 0
    return out


def _lines(path):
    return [json.loads(x) for x in path.read_text().splitlines()]


def test_render_writes_frames_ground_truth_and_camera(rendered):
    gt = json.loads((rendered / "ground_truth.json").read_text())
    assert len(gt["frames"]) == 4
    assert all((rendered / f["file"]).is_file() for f in gt["frames"])
    assert (rendered / "camera.yml").is_file()


def test_detect_folder_with_poses_annotations_and_rerun(rendered, tmp_path, capsys):
    out = tmp_path / "det.jsonl"
    code = main(["detect", str(rendered), "--camera", str(rendered / "camera.yml"), "--marker-length", "0.15",
                 "--out", str(out), "--annotate", str(tmp_path / "ann"), "--rerun", str(tmp_path / "run.rrd")])
    assert code == 0
    records = _lines(out)
    gt = json.loads((rendered / "ground_truth.json").read_text())
    assert [r["frame"] for r in records] == [0, 1, 2, 3]
    for rec, frame in zip(records, gt["frames"], strict=True):
        want = sorted(m["id"] for m in frame["markers"] if m["visible"])
        assert sorted(m["id"] for m in rec["markers"]) == want
        for m in rec["markers"]:
            truth = next(t for t in frame["markers"] if t["id"] == m["id"])
            assert np.abs(np.array(m["corners"]) - np.array(truth["corners"])).max() < 0.5
            assert np.linalg.norm(np.array(m["tvec"]) - np.array(truth["tvec"])) < 0.01
            assert m["reprojection_rms_px"] < 0.5
    assert len(list((tmp_path / "ann").glob("*.png"))) == 4
    assert (tmp_path / "run.rrd").stat().st_size > 0
    assert "4 frames" in capsys.readouterr().err


def test_fast_search_finds_the_rendered_markers(tmp_path):
    from visloc.cli import build_parser
    from visloc.commands._common import detector_for
    from visloc.markers import FAST_PASSES

    assert detector_for(build_parser().parse_args(["detect", "x", "--fast"])).params.passes == FAST_PASSES
    assert detector_for(build_parser().parse_args(["detect", "x"])).params.passes != FAST_PASSES
    for argv in (["localize", "x", "--camera", "c", "--map", "m"], ["track", "x", "--camera", "c", "--body", "b",
                                                                     "--reference", "r"]):
        assert build_parser().parse_args([*argv, "--fast"]).fast
    src = tmp_path / "frames"
    assert main(["render", "markers", str(src), "--n", "3", "--seed", "5", "--size", "640x480"]) == 0
    out = tmp_path / "fast.jsonl"
    assert main(["detect", str(src), "--fast", "--out", str(out), "--quiet"]) == 0
    gt = json.loads((src / "ground_truth.json").read_text())
    for rec, frame in zip(_lines(out), gt["frames"], strict=True):
        want = sorted(m["id"] for m in frame["markers"] if m["visible"])
        assert sorted(m["id"] for m in rec["markers"]) == want


def test_corrupt_image_is_reported_and_the_run_goes_on(rendered, tmp_path, capsys):
    folder = tmp_path / "frames"
    folder.mkdir()
    for p in sorted(rendered.glob("frame_*.png"))[:2]:
        (folder / p.name).write_bytes(p.read_bytes())
    (folder / "frame_0001b.png").write_bytes(b"not a png at all")
    out = tmp_path / "det.jsonl"
    assert main(["detect", str(folder), "--out", str(out), "--quiet"]) == 1
    records = _lines(out)
    assert len(records) == 3
    assert [r["frame"] for r in records] == [0, 1, 2]  # sorted: frame_0000, frame_0001, frame_0001b
    assert "error" in records[2] and "frame_0001b.png" in records[2]["source"]
    assert all("time" in r for r in records)  # an unreadable frame keeps its time, as localize's rows do
    assert all(r["markers"] for r in records[:2])
    err = capsys.readouterr().err
    assert err.count("warning") == 1 and "frame_0001b.png" in err


def test_max_frames_counts_the_frames_processed_not_those_skipped_before_the_range(rendered, tmp_path):
    out = tmp_path / "range.jsonl"
    assert main(["detect", str(rendered), "--frame-range", "1:", "--max-frames", "2", "--out", str(out), "--quiet"]) == 0
    assert [r["frame"] for r in _lines(out)] == [1, 2]


def test_a_frame_range_past_the_end_is_a_usage_error(rendered, tmp_path, capsys):
    # it used to succeed with "0 frames" and no output file at all
    n = len(list(rendered.glob("*.png")))
    out = tmp_path / "range.jsonl"
    assert main(["detect", str(rendered), "--frame-range", f"{n}:", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"starts past the end of the source ({n} frames)" in err
    assert not out.exists()


def test_detect_video(tmp_path):
    assert main(["render", "markers", str(tmp_path), "--video", "--n", "12", "--size", "320x240"]) == 0
    video = tmp_path / "markers.mp4"
    cap = cv2.VideoCapture(str(video))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 12
    cap.release()
    out = tmp_path / "v.jsonl"
    assert main(["detect", str(video), "--out", str(out), "--quiet"]) == 0
    records = _lines(out)
    assert len(records) == 12
    assert sum(len(r["markers"]) for r in records) > 0
    assert records[1]["time"] > records[0]["time"]


def test_explain_writes_stage_pictures(rendered, tmp_path):
    img = min(rendered.glob("frame_*.png"))
    assert main(["detect", str(img), "--explain", str(tmp_path / "ex"), "--quiet"]) == 0
    names = {p.name for p in (tmp_path / "ex").iterdir()}
    assert "frame_000000_I_detections.png" in names and "frame_000000_candidates.json" in names


@pytest.mark.parametrize(
    "args, message",
    [
        (["detect", "/no/such/path.png"], "does not exist"),
        (["detect", "{rendered}", "--dict", "DICT_NOPE"], "unknown dictionary"),
        (["detect", "{rendered}", "--camera", "{bad_camera}", "--marker-length", "0.1"], "camera"),
        (["detect", "{rendered}", "--marker-length", "-1"], "marker-length"),
        (["detect", "{rendered}", "--marker-length", "0.1"], "--camera"),
    ],
)
def test_configuration_errors_are_one_line_and_exit_2(rendered, tmp_path, capsys, args, message):
    bad = tmp_path / "bad.yml"
    bad.write_text("%YAML:1.0\ncamera_matrix: 3\n")
    argv = [a.format(rendered=rendered, bad_camera=bad) for a in args]
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own checks
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and message in err
    assert "Traceback" not in err


def test_demo_prints_a_table_and_writes_outputs(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "demo"), "--frames", "2"]) == 0
    text = capsys.readouterr().out
    assert "corner RMS px" in text and "markers found" in text
    assert "side step" in text and "Hover on visloc's vision" in text
    rows = (tmp_path / "demo" / "sidestep.csv").read_text().splitlines()
    assert rows[0].startswith("t,x,y,z") and len(rows) == 1202
    assert len(_lines(tmp_path / "demo" / "detections.jsonl")) == 2
    assert len(list((tmp_path / "demo" / "annotated").glob("*.png"))) == 2


def test_no_command_prints_help():
    assert main([]) == 2


def test_an_interrupted_run_keeps_the_frames_already_written(rendered, tmp_path, monkeypatch, capsys):
    from visloc.markers import MarkerDetector

    calls = {"n": 0}
    real = MarkerDetector.detect

    def detect_then_interrupt(self, image):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real(self, image)

    monkeypatch.setattr(MarkerDetector, "detect", detect_then_interrupt)
    out = tmp_path / "partial.jsonl"
    assert main(["detect", str(rendered), "--out", str(out), "--quiet"]) == 130
    assert [r["frame"] for r in _lines(out)] == [0, 1]
    assert "interrupted" in capsys.readouterr().err


def test_model_json_has_the_hover_trim(capsys):
    import json as _json

    assert main(["model", "--json"]) == 0
    d = _json.loads(capsys.readouterr().out)
    m, g, c, k = d["mass_kg"], d["g"], d["thrust_coefficient_c_mean"], d["pwm_shift_k"]
    assert d["hover_pwm_percent"] == pytest.approx([np.sqrt(m * g / (4 * c)) - k] * 4, abs=1e-9)
    assert round(d["hover_pwm_percent"][0], 1) == 66.9
    assert len(d["open_loop_poles"]) == 12 and max(p[0] for p in d["open_loop_poles"]) < 1e-6
    assert main(["model"]) == 0 and "hover" in capsys.readouterr().out


def test_robust_json_reports_a_stable_polytope_and_rejects_a_sigma_beyond_the_box(capsys):
    # robust --json prints visloc.control.robust_summary (its one LMI run at 1 sigma is this)
    assert main(["robust", "--sigma", "1", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert {"vertices", "vertex_stable", "max_real_eig", "lyapunov", "n_sigma", "arm_m", "states"} <= set(s)
    assert s["vertices"] == 256 and s["vertex_stable"] is True and s["states"] == 16
    assert isinstance(s["max_real_eig"], float) and s["max_real_eig"] < 0
    try:
        import cvxpy  # noqa: F401

        assert s["lyapunov"] == "feasible"
    except ImportError:
        assert s["lyapunov"] == "unavailable"
    assert main(["robust", "--sigma", "99"]) == 2
    assert "--sigma must be from 0 to below 8.394610202" in capsys.readouterr().err
    assert main(["robust", "--sigma", "8.3949"]) == 2  # the bound used to be rounded to 8.395 in the message
    assert "below 8.394610202" in capsys.readouterr().err
    assert main(["robust", "--tilt", "50"]) == 2  # the tracking loop's check: below 45 degrees
    assert "--tilt" in capsys.readouterr().err


def test_border_bits_inverted_and_confidence_from_the_command_line(tmp_path):
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    sheet = np.full((200, 400), 255, np.uint8)
    sheet[40:160, 40:160] = cv2.aruco.generateImageMarker(d, 12, 120, borderBits=2)
    sheet[20:180, 220:380] = 0  # a white-on-black marker on a black card
    sheet[40:160, 240:360] = 255 - cv2.aruco.generateImageMarker(d, 31, 120)
    cv2.imwrite(str(tmp_path / "sheet.png"), cv2.GaussianBlur(sheet, (0, 0), 0.7))
    out = tmp_path / "m.jsonl"
    assert main(["detect", str(tmp_path / "sheet.png"), "--border-bits", "2", "--out", str(out), "--quiet"]) == 0
    (rec,) = _lines(out)
    assert [m["id"] for m in rec["markers"]] == [12] and rec["markers"][0]["confidence"] > 0.9
    assert main(["detect", str(tmp_path / "sheet.png"), "--inverted", "both", "--out", str(out), "--quiet"]) == 0
    (rec,) = _lines(out)
    assert [(m["id"], m.get("inverted", False)) for m in rec["markers"]] == [(31, True)]


def _copy_frames(rendered, folder, n=2):
    folder.mkdir()
    for p in sorted(rendered.glob("frame_*.png"))[:n]:
        (folder / p.name).write_bytes(p.read_bytes())
    return sorted(folder.glob("*.png"))


@pytest.mark.parametrize("case", ["out is the image", "annotate is the folder", "out in the folder",
                                  "annotate holds the image", "out is the camera", "rerun via a glob"])
def test_an_output_that_would_overwrite_an_input_is_refused(rendered, tmp_path, capsys, case):
    frames = _copy_frames(rendered, tmp_path / "in")
    before = {p: p.read_bytes() for p in frames}
    cam = tmp_path / "camera.yml"
    cam.write_bytes((rendered / "camera.yml").read_bytes())
    argv = {
        "out is the image": ["detect", str(frames[0]), "--out", str(frames[0])],
        "annotate is the folder": ["detect", str(tmp_path / "in"), "--annotate", str(tmp_path / "in")],
        "out in the folder": ["detect", str(tmp_path / "in"), "--out", str(tmp_path / "in" / "det.jsonl")],
        "annotate holds the image": ["detect", str(frames[0]), "--annotate", str(tmp_path / "in")],
        "out is the camera": ["detect", str(frames[0]), "--camera", str(cam), "--marker-length", "0.1",
                              "--out", str(cam)],
        "rerun via a glob": ["detect", str(tmp_path / "in" / "*.png"), "--rerun", str(frames[1])],
    }[case]
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "overwritten" in err or "write outputs elsewhere" in err
    assert {p: p.read_bytes() for p in frames} == before  # nothing touched
    assert cam.read_bytes() == (rendered / "camera.yml").read_bytes()


def test_an_internal_error_is_one_line_exit_3_and_debug_anywhere_shows_it(rendered, capsys, monkeypatch):
    from visloc.commands import markers  # the module `visloc detect` runs from

    def broken(args):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(markers, "detect", broken)
    img = str(min(rendered.glob("frame_*.png")))
    assert main(["detect", img]) == 3
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "internal error" in err and "--debug" in err
    with pytest.raises(ZeroDivisionError):
        main(["detect", img, "--debug"])  # after the sub-command too


def test_a_value_error_once_the_frames_run_is_visloc_s_fault(rendered, capsys, monkeypatch):
    from visloc.markers import MarkerDetector

    def broken(self, image):
        raise ValueError("an internal check failed")

    monkeypatch.setattr(MarkerDetector, "detect", broken)
    assert main(["detect", str(min(rendered.glob("frame_*.png"))), "--quiet"]) == 3  # inputs were fine
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "internal error: ValueError" in err
    assert main(["detect", str(rendered), "--dict", "DICT_NOPE"]) == 2  # before the frames: the input's fault


def test_a_sub_command_imports_only_what_it_needs(tmp_path):
    # `visloc model` and a missing input answer without loading OpenCV, rerun or scipy.spatial
    # (each takes a large part of a second to import)
    import subprocess
    import sys

    probe = ("import sys; from visloc.cli import main; code = main({argv!r}); "
             "print(code, sorted(m for m in ('cv2', 'rerun', 'scipy.spatial') if m in sys.modules))")
    for argv, code in ((["model", "--json"], 0), (["detect", str(tmp_path / "none.png")], 2),
                       (["flow", str(tmp_path), "--camera", str(tmp_path / "none.yml"), "--height", "1"], 2)):
        out = subprocess.run([sys.executable, "-c", probe.format(argv=argv)], capture_output=True, text=True,
                             check=True).stdout.strip().splitlines()[-1]
        assert out == f"{code} []", (argv, out)


@pytest.mark.parametrize("argv, message", [
    (["sim", "hover", "--seed", "-1"], "--seed: must be at least 0 (a random seed)"),
    (["demo", "--frames", "1000000"], "--frames: must be at most 1000"),  # ran for hours before  # numpy's words, without the option, before
    (["render", "markers", "{tmp}/v", "--n", "1", "--video"], "--n must be at least 2 for --video"),
    (["detect", "{frame}", "--explain", "{tmp}/cam.yml"], "a file, not a folder"),  # [Errno 17] File exists
    (["detect", "{frame}", "--annotate", "{tmp}/v/a.txt"], "names a .txt file"),  # made a folder named a.txt
    (["detect", "{frame}", "--out", "/proc/visloc-test/x.jsonl"], "cannot write /proc/visloc-test/x.jsonl"),
    (["detect", "/dev/null"], "/dev/null is neither a file nor a folder"),  # "does not exist"
    (["localize", "{frame}", "--camera", "{tmp}/cam.yml", "--map", "{tmp}/nan.yml"], "corners must be finite, got"),
    (["calibrate", "{frame}", "--board", "{tmp}/cam.yml", "--out", "{tmp}/c.yml"],
     "neither a ChArUco board file (board_type: charuco) nor a marker map"),
])
def test_messages_name_the_problem(rendered, tmp_path, capsys, argv, message):
    from visloc.pose import Camera

    Camera(np.array([[300.0, 0.0, 160.0], [0.0, 300.0, 120.0], [0.0, 0.0, 1.0]]), size=(320, 240)).to_file(
        tmp_path / "cam.yml")
    (tmp_path / "nan.yml").write_text("%YAML:1.0\nmarkers:\n  - { id: 0, corners: [ .nan, 0., 0., 0.1, 0., 0., "
                                      "0.1, -0.1, 0., 0., -0.1, 0. ] }\n")
    frame = min(rendered.glob("*.png"))
    try:
        code = main([a.format(tmp=tmp_path, frame=frame) for a in argv])
    except SystemExit as exc:  # argparse's own checks
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and message in err and "Errno" not in err and ".partial" not in err
    assert not (tmp_path / "v").exists()


@pytest.mark.parametrize("command, options, message", [
    ("flow", "", "the following arguments are required: --camera"),
    ("detect", "--max-frames 0", "--max-frames: must be at least 1"),
])
def test_batch_options_the_command_refuses_are_one_usage_error(rendered, tmp_path, capsys, command, options, message):
    # each recording used to fail on its own (exit 1, one warning per recording)
    out = tmp_path / "out"
    code = main(["batch", command, str(rendered), str(rendered), "--options", options, "--outdir", str(out), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and message in err and f"for {command}" in err
    assert not out.exists()


def test_one_parser_serves_every_call_without_carrying_options_over():
    """``main`` reuses one parser per process (``visloc batch`` runs it once per task): options
    of one call must not leak into the next."""
    from visloc.cli import _shared_parser

    parser = _shared_parser()
    assert _shared_parser() is parser
    first = parser.parse_args(["detect", "a.png", "--fast", "--redetect-every", "5", "--inverted", "both"])
    second = parser.parse_args(["detect", "b.png"])
    assert (first.fast, first.redetect_every, first.inverted) == (True, 5, "both")
    assert (second.source, second.fast, second.redetect_every, second.inverted) == ("b.png", False, 1, "no")
