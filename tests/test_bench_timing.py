"""``bench/_timing.py``: the wait for the host's normal speed before timed work."""

import importlib.util
from pathlib import Path

_PATH = Path(__file__).resolve().parents[1] / "bench" / "_timing.py"
_spec = importlib.util.spec_from_file_location("bench_timing", _PATH)
timing = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(timing)


def test_a_check_that_cannot_pass_gives_up_after_max_wait_and_is_counted():
    st = timing.Steady(tolerance=0.0, max_wait=0.0)  # the reference can never run in no time
    st.wait()
    s = st.summary()
    assert (s["checks"], s["waits"], s["gave_up"]) == (1, 1, 1)
    assert s["reference_ms_normal"] > 0


def test_a_check_that_always_passes_never_waits_and_every_skips_checks():
    st = timing.Steady(tolerance=1e9)
    st.wait()
    st.wait(every=3600.0)  # the last check was under an hour ago: skipped
    s = st.summary()
    assert (s["checks"], s["waits"], s["gave_up"], s["waited_s"]) == (1, 0, 0, 0.0)


def test_the_shared_steady_is_one_object():
    assert timing.steady() is timing.steady()


def test_best_per_item_takes_each_items_fastest_round():
    times = [3.0, 1.0, 5.0,   # round 0 over three items
             2.0, 4.0, 6.0]   # round 1
    assert timing.best_per_item(times, 2).tolist() == [2.0, 1.0, 5.0]


def _store(path, normal_s, age_s=0.0):
    import json
    import time
    path.write_text(json.dumps({"normal_s": normal_s, "time": time.time() - age_s}))
    return path


def test_a_stored_normal_time_makes_a_process_that_starts_slow_wait(tmp_path):
    # a stored normal no run can reach: the new process must not take its own speed for normal
    st = timing.Steady(max_wait=0.0, store=_store(tmp_path / "s.json", 1e-9))
    st.wait()
    s = st.summary()
    assert (s["waits"], s["gave_up"]) == (1, 1)
    assert s["reference_ms_stored"] == 0.0 and s["reference_ms_normal"] == 0.0


def test_its_own_checks_outvote_a_stored_time_the_host_no_longer_reaches(tmp_path):
    st = timing.Steady(max_wait=0.0, store=_store(tmp_path / "s.json", 1e-9))
    for _ in range(80):
        st._probe()
    assert st.normal > 1e-6  # 120 checks, 20 of them stored: the 20th percentile is its own


def test_a_stale_or_broken_store_is_ignored_and_a_long_run_writes_it(tmp_path):
    assert timing.Steady(store=_store(tmp_path / "old.json", 1e-9, age_s=7200.0)).seeded is None
    (tmp_path / "bad.json").write_text("{not json")
    assert timing.Steady(store=tmp_path / "bad.json").seeded is None
    path = tmp_path / "new.json"
    st = timing.Steady(tolerance=1e9, store=path)
    for _ in range(99):
        st.wait()
    st.summary()
    assert not path.exists()  # fewer than 100 checks: its normal is not trusted for others
    st.wait()
    st.summary()
    assert abs(timing.Steady(store=path).seeded - st.normal) < 1e-12
