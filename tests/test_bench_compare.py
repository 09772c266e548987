"""``bench/compare.py``: two runs' Markdown results compared number by number."""

import importlib.util
import json
from pathlib import Path

import pytest

_PATH = Path(__file__).resolve().parents[1] / "bench" / "compare.py"
_spec = importlib.util.spec_from_file_location("bench_compare", _PATH)
compare = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(compare)


@pytest.mark.parametrize(("a", "b", "tol", "expected"), [
    ("1.00", "1.20", 0.15, True),     # 17 % of the larger
    ("1.00", "1.10", 0.15, False),    # 9 %
    ("0.04", "0.05", 0.15, False),    # 20 %, but one unit of the last digit: rounding
    ("0.04", "0.06", 0.15, True),     # two units
    ("12", "14", 0.10, True),
    ("0", "0.00", 0.15, False),
    ("-2.0", "2.0", 0.15, True),
])
def test_differs(a, b, tol, expected):
    assert compare.differs(a, b, tol) is expected


def _write(folder: Path, name: str, text: str) -> None:
    folder.mkdir(exist_ok=True)
    (folder / f"{name}.md").write_text(text)


def test_main_lists_the_cells_beyond_the_tolerance(tmp_path, capsys):
    old, new = tmp_path / "old", tmp_path / "new"
    table = "**t** (3 rounds)\n\n| method | ms | ratio |\n|---|---|---|\n| visloc | {} | {} |\n| opencv | 2.00 | 1.00 |\n"
    _write(old, "x", table.format("1.00", "0.50"))
    _write(new, "x", table.format("1.05", "0.50"))
    assert compare.main([str(old), str(new)]) == 0
    _write(new, "x", table.format("1.40", "0.70"))
    assert compare.main([str(old), str(new)]) == 1
    out = capsys.readouterr().out
    assert "x.md:5 [visloc] cell 1: 1.00 -> 1.40" in out
    assert "x.md:5 [visloc] cell 2: 0.50 -> 0.70" in out
    assert "opencv" not in out


def test_changed_shape_and_bad_input(tmp_path, capsys):
    old, new = tmp_path / "old", tmp_path / "new"
    _write(old, "x", "| a | 1 |\n")
    _write(new, "x", "| a | 1 |\n| b | 2 |\n")
    assert compare.main([str(old), str(new)]) == 1
    assert "not compared" in capsys.readouterr().out
    assert compare.main([str(old), str(tmp_path / "missing")]) == 2
    assert compare.main([str(old), str(new), "--tol", "1.5"]) == 2


def test_host_reference_is_printed_where_both_runs_record_it(tmp_path, capsys):
    old, new = tmp_path / "old", tmp_path / "new"
    for folder, ref in ((old, 0.3), (new, 0.45)):
        _write(folder, "x", "| a | 1 |\n")
        (folder / "x.json").write_text(json.dumps({"steady": {"reference_ms_normal": ref}}))
    assert compare.main([str(old), str(new)]) == 0
    assert "host reference workload: 0.300 -> 0.450 ms)" in capsys.readouterr().out
    for folder, waits in ((old, 4), (new, 29)):
        (folder / "x.json").write_text(json.dumps({"steady": {"reference_ms_normal": 0.4, "checks": 40, "waits": waits}}))
    assert compare.main([str(old), str(new)]) == 0
    assert "(host reference workload: 0.400 -> 0.400 ms; waited at 4/40 -> 29/40 checks)" in capsys.readouterr().out
    (new / "x.json").write_text("{}")  # no record: nothing printed
    assert compare.main([str(old), str(new)]) == 0
    assert "host reference" not in capsys.readouterr().out
