"""``visloc track`` and ``visloc render map`` through ``main([...])``."""

import json
import socket

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.pose.test_relative import BODY, REFERENCE, SIZE, write_track_inputs
from visloc.cli import main
from visloc.markers import MarkerDetector
from visloc.pose.maps import MarkerMap
from visloc.synth import default_camera, write_camera_yml


def test_track_writes_poses_and_sends_udp(tmp_path):
    truth = write_track_inputs(tmp_path, 2.0, 4)  # the body moves 2 cm along x per frame, turning slowly
    frames = tmp_path / "frames"
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(2.0)
    port = rx.getsockname()[1]
    out = tmp_path / "track.jsonl"
    code = main(["track", str(frames), "--camera", str(tmp_path / "cam.yml"), "--body", str(tmp_path / "body.yml"),
                 "--reference", str(tmp_path / "ref.yml"), "--fps", "30", "--out", str(out), "--udp", f"127.0.0.1:{port}",
                 "--quiet"])
    assert code == 0
    recs = [json.loads(x) for x in out.read_text().splitlines()]
    assert len(recs) == 4
    for rec, T in zip(recs, truth, strict=True):
        assert abs(rec["x"] - T.t[0]) < 0.01 and abs(rec["y"] - T.t[1]) < 0.01
        assert abs(np.degrees(rec["yaw"]) - np.degrees(Rotation.from_matrix(T.R).as_euler("zyx")[0])) < 0.5
    vx = [r["vx"] for r in recs]  # moving +x at 0.6 m/s: the observer (poles -4) converges towards it
    assert 0 < vx[1] < vx[2] < vx[3] < 0.6
    got = [json.loads(rx.recv(65536)) for _ in range(4)]
    rx.close()
    assert [g["frame"] for g in got] == [0, 1, 2, 3]


def test_render_map_makes_a_detectable_sheet(tmp_path):
    REFERENCE.to_file(tmp_path / "ref.yml")
    assert main(["render", "map", str(tmp_path / "ref.yml"), str(tmp_path / "sheet.png"), "--dpi", "150"]) == 0
    img = cv2.imread(str(tmp_path / "sheet.png"), cv2.IMREAD_GRAYSCALE)
    px_per_m = 150 / 0.0254
    assert abs(img.shape[1] - (0.28 + 0.04) * px_per_m) < 2  # 2 x 12 cm + 4 cm gap + 2 x 2 cm margin
    dets = MarkerDetector("DICT_4X4_50").detect(cv2.copyMakeBorder(img, 20, 20, 20, 20, cv2.BORDER_CONSTANT, value=255))
    assert sorted(d.id for d in dets) == [0, 1, 2, 3]
    # marker 0's top-left corner at the sheet's margin: 2 cm in from the top-left corner
    d0 = next(d for d in dets if d.id == 0)
    assert np.allclose(d0.corners[0] - 20, 0.02 * px_per_m - 0.5, atol=1.0)
    assert isinstance(MarkerMap.from_file(tmp_path / "ref.yml"), MarkerMap)


def _one_blank_frame_and_files(tmp_path):
    """A folder of one blank frame, body.yml, ref.yml and cam.yml in ``tmp_path``; the folder."""
    frames = tmp_path / "frames"
    frames.mkdir()
    cv2.imwrite(str(frames / "f0.png"), np.zeros((48, 64), np.uint8))
    BODY.to_file(tmp_path / "body.yml")
    REFERENCE.to_file(tmp_path / "ref.yml")
    write_camera_yml(tmp_path / "cam.yml", default_camera(SIZE), SIZE)
    return frames


def test_track_needs_fps_for_an_image_folder(tmp_path, capsys):
    frames = _one_blank_frame_and_files(tmp_path)
    code = main(["track", str(frames), "--camera", str(tmp_path / "cam.yml"), "--body", str(tmp_path / "body.yml"),
                 "--reference", str(tmp_path / "ref.yml"), "--quiet"])
    assert code == 2
    assert "--fps" in capsys.readouterr().err


@pytest.mark.parametrize("argv, message", [
    (["render", "map", "{ref}", "{tmp}/sheet"], "cannot write an image"),
    (["render", "map", "{ref}", "{tmp}/sheet.png", "--dpi", "1e6"], "at most 2400"),
    (["render", "map", "{ref}", "{ref}"], "overwritten"),
    (["render", "localize", "{tmp}/loc", "--seconds", "1e9"], "at most 5000"),
    (["sim", "hover", "--seconds", "1e8"], "at most 3600"),
])
def test_requests_it_cannot_meet_are_one_line_errors_before_any_work(tmp_path, capsys, argv, message):
    REFERENCE.to_file(tmp_path / "ref.yml")
    before = (tmp_path / "ref.yml").read_bytes()
    try:
        code = main([a.format(ref=tmp_path / "ref.yml", tmp=tmp_path) for a in argv])
    except SystemExit as exc:  # argparse's own checks
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and message in err
    assert (tmp_path / "ref.yml").read_bytes() == before
    assert not (tmp_path / "loc").exists() and not (tmp_path / "sheet").exists()


@pytest.mark.parametrize("maps, poles, message", [
    (("body", "ref"), ["0", "0"], "--poles: poles must have negative real parts"),
    (("body", "ref"), ["nan", "-4"], "--poles"),
    (("ref", "ref"), ["-4", "-4"], "share marker ids"),
])
def test_track_options_it_cannot_use_are_usage_errors(tmp_path, capsys, maps, poles, message):
    # they used to end in an "internal error" (exit 3) at the first frame with the body in view
    frames = _one_blank_frame_and_files(tmp_path)
    code = main(["track", str(frames), "--fps", "30", "--camera", str(tmp_path / "cam.yml"),
                 "--body", str(tmp_path / f"{maps[0]}.yml"), "--reference", str(tmp_path / f"{maps[1]}.yml"),
                 "--poles", *poles, "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and message in err
