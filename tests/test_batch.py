"""``visloc batch`` on a real Dask engine: a LocalCluster of worker processes, and a scheduler
with two workers started here on loopback, one of them killed mid-run."""

import csv
import importlib.util
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from visloc.batch import run_batch
from visloc.cli import main


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    root = tmp_path_factory.mktemp("batch")
    videos = []
    for seed in (1, 2, 3):
        assert main(["render", "markers", str(root / f"r{seed}"), "--video", "--n", "6", "--size", "320x240",
                     "--seed", str(seed)]) == 0
        videos.append(shutil.move(root / f"r{seed}" / "markers.mp4", root / f"v{seed}.mp4"))
    (root / "broken.mp4").write_text("not a video\n")
    serial = {}
    for v in videos:  # what plain `visloc detect` writes, one recording at a time
        out = root / f"serial_{Path(v).stem}.jsonl"
        assert main(["detect", str(v), "--dict", "DICT_4X4_50", "--out", str(out), "--quiet"]) == 0
        serial[Path(v).stem] = out.read_bytes()
    return root, [str(v) for v in videos], serial


@pytest.fixture(scope="module")
def cluster():
    """Two worker processes for the module's batches (each imports visloc once)."""
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as c:
        yield c.scheduler_address


def _summary(outdir: Path) -> dict[str, dict]:
    return {Path(r["recording"]).stem: r for r in csv.DictReader((outdir / "summary.csv").open())}


def test_local_cluster_writes_what_serial_runs_write_and_reruns_only_what_is_missing(recordings, cluster, tmp_path,
                                                                                     capsys):
    root, videos, serial = recordings
    out = tmp_path / "out"
    argv = ["batch", "detect", *videos, str(root / "broken.mp4"), "--outdir", str(out), "--scheduler", cluster,
            "--options", "--dict DICT_4X4_50", "--quiet"]
    assert main(argv) == 1  # the broken recording failed; the batch went on
    for stem, data in serial.items():
        assert (out / f"{stem}.jsonl").read_bytes() == data  # byte for byte the serial run's output
    s = _summary(out)
    assert {k: s[k]["status"] for k in s} == {"v1": "done", "v2": "done", "v3": "done", "broken": "failed"}
    assert "cannot open video" in s["broken"]["message"] and not (out / "broken.jsonl").exists()
    assert not list(out.glob("*.part"))  # no partial file left behind
    assert all(s[k]["rows"] == "6" for k in ("v1", "v2", "v3"))
    if importlib.util.find_spec("pyarrow") is not None:  # the Parquet summary is written only where pyarrow is
        import pyarrow.parquet as pq

        table = pq.read_table(out / "summary.parquet").to_pylist()
        assert {Path(r["recording"]).stem: (r["status"], r["rows"]) for r in table} == {
            k: (v["status"], int(v["rows"])) for k, v in s.items()}
    else:
        assert not (out / "summary.parquet").exists()
    (out / "v2.jsonl").unlink()
    assert main(argv) == 1
    s = _summary(out)
    assert [s[k]["status"] for k in ("v1", "v2", "v3")] == ["skipped", "done", "skipped"]
    assert (out / "v2.jsonl").read_bytes() == serial["v2"]
    assert main([*argv[:-3], "--options", "--dict DICT_4X4_50 --fast", "--quiet"]) == 1  # other options: all again
    assert [_summary(out)[k]["status"] for k in ("v1", "v2", "v3")] == ["done"] * 3
    capsys.readouterr()
    assert main(["batch", "detect", videos[0], "--outdir", str(tmp_path / "o2"), "--options", "--out x.jsonl"]) == 2
    assert "leave --out" in capsys.readouterr().err


def test_workers_start_a_local_cluster_of_their_own(recordings, tmp_path):
    _, videos, serial = recordings
    assert main(["batch", "detect", videos[0], "--outdir", str(tmp_path), "--workers", "1", "--quiet"]) == 0
    assert (tmp_path / "v1.jsonl").read_bytes() == serial["v1"]


def _start(args: list[str], log: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", *args], stdout=log.open("w"), stderr=subprocess.STDOUT,
                            start_new_session=True)


def test_a_worker_killed_mid_run_loses_no_recording(recordings, tmp_path):
    _, videos, serial = recordings
    port = 20000 + os.getpid() % 20000
    address = f"tcp://127.0.0.1:{port}"
    procs = [_start(["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", str(port),
                     "--dashboard-address", ":0", "--no-show"], tmp_path / "scheduler.log")]
    try:
        for k in range(2):
            procs.append(_start(["distributed.cli.dask_worker", address, "--nworkers", "1", "--nthreads", "1",
                                 "--no-dashboard", "--name", f"w{k}"], tmp_path / f"worker{k}.log"))
        from dask.distributed import Client

        with Client(address, timeout=30) as client:  # retries until the scheduler is up
            client.wait_for_workers(2, timeout=30)
        many = videos * 4  # twelve tasks; outputs need distinct names: copies of the videos
        copies = []
        for i, v in enumerate(many):
            c = tmp_path / f"rec{i:02d}.mp4"
            shutil.copy(v, c)
            copies.append(str(c))

        def kill_one_worker(res):
            if len(done) == 2:
                os.killpg(procs[1].pid, signal.SIGKILL)
            done.append(res)

        done = []
        results = run_batch("detect", copies, "--dict DICT_4X4_50", tmp_path / "out", scheduler=address,
                            progress=kill_one_worker)
        assert procs[1].poll() is not None  # it was killed while tasks remained
        assert sorted(r.recording for r in results) == sorted(copies) and {r.status for r in results} == {"done"}
        for i, v in enumerate(many):
            assert (tmp_path / "out" / f"rec{i:02d}.jsonl").read_bytes() == serial[Path(v).stem].replace(
                str(v).encode(), copies[i].encode())
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in procs:
            p.wait(timeout=10)


def test_chunked_videos_join_into_the_unchunked_output(recordings, cluster, tmp_path, capsys):
    _, videos, serial = recordings
    out = tmp_path / "chunked"
    # six frames a video in chunks of 2: three tasks each, joined in frame order
    assert main(["batch", "detect", *videos, "--outdir", str(out), "--scheduler", cluster, "--chunk", "2",
                 "--options", "--dict DICT_4X4_50", "--quiet"]) == 0
    for stem, data in serial.items():
        assert (out / f"{stem}.jsonl").read_bytes() == data
    assert sorted(p.name for p in out.glob("*.jsonl")) == ["v1.jsonl", "v2.jsonl", "v3.jsonl"]
    assert not list(out.glob("*.chunk*")) and not list(out.glob("*.part"))  # the chunks' files are gone
    assert main(["batch", "flow", *videos, "--outdir", str(out / "f"), "--chunk", "2"]) == 2
    assert "--chunk needs detect" in capsys.readouterr().err


def test_frame_range_keeps_the_sources_indices_and_times(recordings, tmp_path):
    _, videos, serial = recordings
    parts = []
    for k, rng in enumerate(["0:2", "2:5", "5:"]):
        out = tmp_path / f"p{k}.jsonl"
        assert main(["detect", videos[1], "--dict", "DICT_4X4_50", "--frame-range", rng, "--out", str(out),
                     "--quiet"]) == 0
        parts.append(out.read_bytes())
    assert b"".join(parts) == serial["v2"] and parts[1].count(b"\n") == 3
    with pytest.raises(SystemExit):
        main(["detect", videos[1], "--frame-range", "4:2"])


def test_a_job_file_runs_like_the_command_line(recordings, cluster, tmp_path, capsys):
    root, videos, serial = recordings
    job = root / "job.toml"  # relative paths are the job file's
    job.write_text(f'command = "detect"\nrecordings = ["v*.mp4"]\noutdir = "{tmp_path / "job"}"\n'
                   f'options = "--dict DICT_4X4_50"\nscheduler = "{cluster}"\nchunk = 4\n')
    assert main(["batch", "--job", str(job), "--quiet"]) == 0
    for stem, data in serial.items():
        assert (tmp_path / "job" / f"{stem}.jsonl").read_bytes() == data
    bad = tmp_path / "bad.toml"
    bad.write_text('command = "detect"\nrecordings = "v1.mp4"\ncolour = 3\n')
    assert main(["batch", "--job", str(bad)]) == 2
    assert "unknown keys colour" in capsys.readouterr().err
    bad.write_text('command = "detect"\nrecordings = "v1.mp4"\n')
    assert main(["batch", "--job", str(bad)]) == 2
    assert "recordings must be a list" in capsys.readouterr().err
    assert main(["batch", "detect", videos[0]]) == 2  # no --outdir anywhere
    assert "batch needs --outdir" in capsys.readouterr().err


def test_outputs_of_other_options_are_never_skipped(recordings, cluster, tmp_path):
    # a batch of one recording under new options, then all of them under those options: the
    # others' outputs, newer than their recordings, were written under the old options
    _, videos, serial = recordings
    out = tmp_path / "out"

    def run(options: str, recs: list[str]) -> dict[str, str]:
        assert main(["batch", "detect", *recs, "--outdir", str(out), "--scheduler", cluster, "--options", options,
                     "--quiet"]) == 0
        return {k: r["status"] for k, r in _summary(out).items()}

    def found() -> dict[str, bool]:  # whether the output holds markers (the 4x4 options' do, the 5x5's none)
        return {p.stem: '"id"' in p.read_text() for p in sorted(out.glob("v*.jsonl"))}

    four, five = "--dict DICT_4X4_50", "--dict DICT_5X5_50"
    assert run(four, videos) == {"v1": "done", "v2": "done", "v3": "done"}
    assert found() == {"v1": True, "v2": True, "v3": True} and (out / "v1.jsonl").read_bytes() == serial["v1"]
    assert run(five, videos[:1]) == {"v1": "done"}
    assert run(five, videos) == {"v1": "skipped", "v2": "done", "v3": "done"}
    assert found() == {"v1": False, "v2": False, "v3": False}  # every output now the new options'
    assert run(four, videos[1:]) == {"v2": "done", "v3": "done"}
    assert run(four, videos) == {"v1": "done", "v2": "skipped", "v3": "skipped"}
    assert found() == {"v1": True, "v2": True, "v3": True} and (out / "v2.jsonl").read_bytes() == serial["v2"]
    os.utime(videos[0])  # v1's recording changed: a batch of it alone, then of all, runs it alone
    assert run(four, videos[:1]) == {"v1": "done"}
    assert run(four, videos) == {"v1": "skipped", "v2": "skipped", "v3": "skipped"}


def test_output_names_depend_on_the_path_alone(tmp_path):
    from visloc.batch import output_name

    (tmp_path / "flight.mp4").write_text("video\n")
    (tmp_path / "run.2024-05-01").mkdir()
    (tmp_path / "Shots.PNG").write_text("image\n")
    for folder in (tmp_path, tmp_path / "missing"):  # the same name whether the recording is there or not
        assert output_name(folder / "flight.mp4", "detect") == "flight.jsonl"
        assert output_name(str(folder / "flight.mp4"), "flow") == "flight.csv"
        assert output_name(folder / "Shots.PNG", "detect") == "Shots.jsonl"
        assert output_name(folder / "lab.bag", "track") == "lab.jsonl"
        assert output_name(folder / "lab.mcap", "localize") == "lab.csv"
        assert output_name(folder / "run.2024-05-01", "detect") == "run.2024-05-01.jsonl"  # a folder's whole name
        assert output_name(f"{folder / 'frames'}/", "detect") == "frames.jsonl"
    with pytest.raises(KeyError):
        output_name("flight.mp4", "render")
