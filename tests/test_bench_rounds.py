"""``bench/_timing.py``'s round order, ``bench/markers.py``'s stage split and ``bench/host_speed.py``'s windows."""

import numpy as np
import pytest

from tests.conftest import load_bench

markers = load_bench("markers")
timing = load_bench("_timing")
host_speed = load_bench("host_speed")


def test_time_sections_runs_every_sections_round_before_the_next_round_and_keeps_each_items_best():
    calls = []
    seconds = iter([0.5, 0.2, 0.9, 0.1, 0.4, 0.3, 0.7, 0.8])  # the self-timed peer's, call by call

    def method(section, name, timed_itself=False):
        def run(item):
            calls.append((section, item, name))
            return ([f"{name}:{item}"], next(seconds)) if timed_itself else [f"{name}:{item}"]
        return run

    sections = [(["a", "b"], {"m": method(0, "m"), "peer": method(0, "peer", True)}),
                (["c", "d"], {"m": method(1, "m"), "peer": method(1, "peer", True)})]
    (best0, out0), (best1, out1) = timing.time_sections(sections, rounds=2)
    assert len(calls) == 16
    assert {(s, i) for s, i, _ in calls[:8]} == {(0, "a"), (0, "b"), (1, "c"), (1, "d")}  # round 1: every item
    assert [s for s, _, _ in calls] == [0, 0, 0, 0, 1, 1, 1, 1] * 2  # section 1's round 1 before section 0's round 2
    # the peer's own times: round 1 gives a, b, c, d = 0.5, 0.2, 0.9, 0.1; round 2 = 0.4, 0.3, 0.7, 0.8
    np.testing.assert_allclose(best0["peer"], [0.4, 0.2])
    np.testing.assert_allclose(best1["peer"], [0.7, 0.1])
    assert best0["m"].shape == (2,) and (best0["m"] > 0).all()
    assert out0 == {"m": [["m:a"], ["m:b"]], "peer": [["peer:a"], ["peer:b"]]}
    assert out1["peer"] == [["peer:c"], ["peer:d"]]


def test_time_sections_calls_between_after_every_sections_round():
    calls = []
    sections = [(["a"], {"m": lambda item: calls.append(("time", item))}),
                (["b"], {"m": lambda item: calls.append(("time", item))})]
    timing.time_sections(sections, rounds=2, between=lambda: calls.append(("between", None)))
    assert calls == [("time", "a"), ("between", None), ("time", "b"), ("between", None)] * 2


def test_stage_split_passes_take_the_sizes_in_turn_and_leave_the_detector_as_it_was():
    import visloc.markers.detector as det_mod

    before = {name: getattr(det_mod, name) for name in markers.STAGES}
    threaded = det_mod._THREAD_MAX_PIXELS
    split = markers.StageSplit({f"{w}x{h}": [sc.image for _, sc in markers.rendered_scenes((w, h), "DICT_4X4_50",
                                                                                         {"easy": 1}, 1)]
                                for w, h in ((160, 120), (200, 150))})
    for _ in range(3):
        split.run_pass()
    assert [len(split.passes[k]) for k in ("160x120", "200x150")] == [2, 1]
    assert {name: getattr(det_mod, name) for name in markers.STAGES} == before
    assert det_mod._THREAD_MAX_PIXELS == threaded
    result = split.result()
    assert result["160x120"]["passes"] == 2 and result["200x150"]["passes"] == 1
    row = result["160x120"]
    assert row["total"] == min(r["total"] for r in split.passes["160x120"])
    assert row["2 blur"] > 0 and row["4-5 contours + filter"] > 0  # the timers ran during the passes
    parts = sum(v for k, v in row.items() if k not in ("total", "passes"))
    assert parts == pytest.approx(row["total"])


def test_host_speed_windows_give_each_windows_fastest_relative_to_the_usual():
    times = np.array([0.0, 1.0, 2.0, 10.0, 11.0, 20.0, 25.0])
    ms = np.array([[1.0, 5.0], [2.0, 4.0], [3.0, 6.0],   # window 0: fastest 1, 4
                   [1.5, 4.0], [2.0, 9.0],               # window 10: 1.5, 4
                   [1.0, 8.0], [1.2, 8.0]])              # window 20: 1, 8
    starts, usual, rel = host_speed.windows(times, ms, 10.0)
    np.testing.assert_allclose(starts, [0, 10, 20])
    np.testing.assert_allclose(usual, [np.percentile([1, 1.5, 1], 10), np.percentile([4, 4, 8], 10)])
    np.testing.assert_allclose(rel, np.array([[1, 4], [1.5, 4], [1, 8]]) / usual)


def test_host_speed_refuses_a_log_shorter_than_two_windows(capsys):
    with pytest.raises(SystemExit) as e:
        host_speed.main(["--seconds", "5", "--window", "10"])
    assert e.value.code == 2
    assert "at least two windows" in capsys.readouterr().err


def test_host_speed_fast_share_counts_the_samples_within_15_percent_of_the_usual():
    ms = np.array([[1.0, 4.0], [1.1, 4.7], [1.2, 4.5], [2.0, 8.0]])
    np.testing.assert_allclose(host_speed.fast_share(ms, np.array([1.0, 4.0])), [0.5, 0.5])


def test_host_speed_refuses_a_busy_cpu_it_cannot_use(capsys):
    import os

    before = os.sched_getaffinity(0)
    cpu = max(before) + 1  # not among this process's CPUs
    with pytest.raises(SystemExit) as e:
        host_speed.main(["--seconds", "20", "--window", "10", "--busy-cpu", str(cpu)])
    assert e.value.code == 2
    assert f"--busy-cpu {cpu}" in capsys.readouterr().err
    assert os.sched_getaffinity(0) == before  # refused before pinning anything
