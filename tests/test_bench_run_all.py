"""``bench/run_all.py``: every bench in turn into one folder, carrying on past a failing one."""

import importlib.util
from pathlib import Path

import pytest

_PATH = Path(__file__).resolve().parents[1] / "bench" / "run_all.py"
_spec = importlib.util.spec_from_file_location("bench_run_all", _PATH)
run_all = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(run_all)

# a bench script's contract: write NAME.md (and .json) into --out; print as it goes
_SCRIPT = """import sys
from pathlib import Path
out = Path(sys.argv[sys.argv.index("--out") + 1])
print("{name} working")
if {fail}:
    sys.exit(3)
(out / "{name}.md").write_text("| a | 1.0 |\\n")
"""


def _scripts(folder: Path, **fail: bool) -> Path:
    for name, bad in fail.items():
        (folder / f"{name}.py").write_text(_SCRIPT.format(name=name, fail=bad))
    return folder


def test_every_script_runs_in_order_and_a_failing_one_does_not_stop_the_rest(tmp_path, capsys):
    (tmp_path / "bench").mkdir()
    bench = _scripts(tmp_path / "bench", first=False, broken=True, last=False)
    out = tmp_path / "new" / "run"
    done = run_all.run_benches(["first", "broken", "last"], out, bench_dir=bench)
    assert list(done) == ["first", "broken", "last"]
    assert [code for code, _ in done.values()] == [0, 3, 0]
    assert (out / "first.md").is_file() and (out / "last.md").is_file() and not (out / "broken.md").exists()
    log = (out / "run_all.log").read_text()
    assert log.index("first working") < log.index("broken working") < log.index("last working")
    assert "==== broken: exit 3" in log
    err = capsys.readouterr().err
    assert "[2/3] broken: FAILED (exit 3" in err and "[3/3] last: done" in err


def test_unknown_bench_names_and_an_out_that_is_a_file_are_refused(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        run_all.main(["--out", str(tmp_path), "--only", "sim", "nosuch"])
    assert e.value.code == 2 and "unknown bench nosuch" in capsys.readouterr().err
    (tmp_path / "file").write_text("")
    with pytest.raises(SystemExit) as e:
        run_all.main(["--out", str(tmp_path / "file")])
    assert e.value.code == 2 and "is not a folder" in capsys.readouterr().err
    assert not (tmp_path / "run_all.log").exists()  # refused before anything ran


def test_the_list_is_the_benches_whose_tables_the_readme_shows():
    readme = (_PATH.parents[1] / "README.md").read_text()
    for name in run_all.BENCHES:
        assert f"bench/{name}.py" in readme
