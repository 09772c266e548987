"""``bench/real_photos_rounds.py``: per-image bests of separate real-photo runs compared, alone
and pooled two runs at a time."""

import importlib.util
import json
from pathlib import Path

_PATH = Path(__file__).resolve().parents[1] / "bench" / "real_photos_rounds.py"
_spec = importlib.util.spec_from_file_location("bench_real_photos_rounds", _PATH)
rounds = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(rounds)


def _run(folder: Path, times: dict[str, list[float]]) -> Path:
    """A real_photos.json with one image and the given per-method rounds (ms)."""
    folder.mkdir()
    methods = {m: {"ms_best": min(t), "ms_rounds": t} for m, t in times.items()}
    methods["apriltag3"] = None   # not run on this dictionary: left out
    (folder / "real_photos.json").write_text(json.dumps({"images": [{"file": "a.jpg", "methods": methods}]}))
    return folder


def test_counts_bests_apart_alone_and_pooled(tmp_path, capsys):
    # visloc's best is 5.0 in runs 0 and 2 and 7.0 in runs 1 and 3; OpenCV's always 3.0
    runs = [_run(tmp_path / f"r{i}", {"visloc": [9.0, 5.0 if i % 2 == 0 else 7.0], "opencv": [3.0, 3.3]})
            for i in range(4)]
    assert rounds.main([str(r) for r in runs]) == 0
    out = capsys.readouterr().out
    assert "4 runs, 2 image/method bests each, rounds per run [2]" in out
    # alone: (0,1) (0,3) (1,2) (2,3) differ in visloc, (0,2) (1,3) do not
    assert "one run: 6 comparisons, bests more than 15% apart 0-1, mean 0.7" in out
    # pooled: every pair of runs holds a 5.0 except (1,3), so (0,2)-(1,3) differs and the others do not
    assert "two runs pooled: 3 comparisons, bests more than 15% apart 0-1, mean 0.3" in out


def test_bad_input_is_exit_2(tmp_path, capsys):
    one = _run(tmp_path / "one", {"visloc": [1.0]})
    assert rounds.main([str(one)]) == 2
    other = tmp_path / "other"
    other.mkdir()
    (other / "real_photos.json").write_text(json.dumps({"images": [{"file": "b.jpg", "methods": {}}]}))
    assert rounds.main([str(one), str(other)]) == 2
    assert rounds.main([str(one), str(tmp_path / "missing")]) == 2
    assert "error" in capsys.readouterr().err
