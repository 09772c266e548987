"""``visloc info`` on image folders: the frame count and size, and a clear answer when no
frame can be read (exit 1, ``readable`` false in the JSON)."""

import json

import cv2
import numpy as np

from visloc.cli import main


def test_a_folder_reports_its_frames_and_size_past_an_unreadable_file(tmp_path, capsys):
    (tmp_path / "a_broken.png").write_bytes(b"not a png")
    cv2.imwrite(str(tmp_path / "b.png"), np.full((48, 64), 128, np.uint8))
    assert main(["info", str(tmp_path), "--json"]) == 0
    facts = json.loads(capsys.readouterr().out)
    assert facts["kind"] == "images" and facts["frames"] == 2
    assert facts["size"] == [64, 48] and facts["readable"] is True


def test_no_readable_frame_is_said_and_exits_1(tmp_path, capsys):
    bad = tmp_path / "broken.png"
    bad.write_bytes(b"not a png")
    assert main(["info", str(bad)]) == 1
    assert "no frame can be read" in capsys.readouterr().out
    assert main(["info", str(bad), "--json"]) == 1
    facts = json.loads(capsys.readouterr().out)
    assert facts["readable"] is False and facts["size"] is None and facts["frames"] == 1
