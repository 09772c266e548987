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
