"""``visloc sim``: JSON fields, written files, exit statuses."""

import csv
import json

from rerun.chunk import RrdReader

from visloc.cli import main


def test_sim_sidestep_json_and_outputs(tmp_path, capsys):
    out, png, rrd = tmp_path / "run.csv", tmp_path / "run.png", tmp_path / "run.rrd"
    code = main(["sim", "sidestep", "--json", "--out", str(out), "--plot", str(png), "--rerun", str(rrd)])
    assert code == 0
    d = json.loads(capsys.readouterr().out)
    assert d["status"] == "settled"
    for key in ("settling_time_s", "overshoot_pct", "position_rms_m", "realtime_factor", "height_dip_m",
                "linear_height_dip_m"):
        assert key in d
    assert d["settling_time_s"] <= 3.0 and d["overshoot_pct"] <= 20.0
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 1201 and float(rows[-1]["t"]) == 6.0
    assert abs(float(rows[-1]["y"]) - 1.0) < 0.05 and float(rows[-1]["sp_y"]) == 1.0
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"
    entities = set(RrdReader(rrd).store().schema().entity_paths())
    assert {"/world/drone", "/world/track", "/plots/position/y/true", "/plots/pwm/motor1"} <= entities


def test_sim_table_and_exit_statuses(capsys):
    assert main(["sim", "push"]) == 0
    text = capsys.readouterr().out
    assert "status: settled" in text and "settling time" in text
    # a camera far too slow for the vision timeout: the estimator loses track -> exit 1
    assert main(["sim", "hover-vision", "--seconds", "2", "--camera-rate", "0.4", "--json"]) == 1
    d = json.loads(capsys.readouterr().out)
    assert d["status"] == "diverged" and "vision lost" in d["reason"]
    assert main(["sim", "hover", "--sigma", "9"]) == 2
    assert "n_sigma" in capsys.readouterr().err
    assert main(["sim", "hover", "--plot", "x.jpg"]) == 2
