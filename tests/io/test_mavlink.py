"""MAVLink out (``visloc.io.mavlink``, ``visloc localize --mavlink``): a real pymavlink
receiver on a loopback port decodes what visloc sends."""

import csv
import json
import math
import socket

import numpy as np
import pytest
from pymavlink import mavutil  # in the test extras (pip install -e ".[test]")

from visloc.cli import main
from visloc.io.mavlink import MAP_FRAMES, MavlinkSink, body_attitude_ned


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _receive(rx, limit: int = 2000) -> list:
    msgs = []
    while len(msgs) < limit and (m := rx.recv_match(blocking=True, timeout=0.3)) is not None:
        if m.get_type() != "BAD_DATA":
            msgs.append(m)
    return msgs


def test_sink_messages_decode_with_their_fields_and_ids():
    port = _free_port()
    rx = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="common")
    cov = np.diag([1e-4, 2e-4, 3e-4, 1e-3, 2e-3, 3e-3])
    with MavlinkSink(f"udpout:127.0.0.1:{port}", component_id=191) as link:
        link.send_vision_position(2.5, (1.0, -2.0, -1.5), (0.1, -0.2, 0.3), covariance=cov, reset_counter=258)
        link.send_odometry(2.6, (1.0, -2.0, -1.5), np.eye(3), (0.5, 0.0, -0.1))
    msgs = _receive(rx)
    rx.close()
    kinds = [m.get_type() for m in msgs]
    assert kinds == ["HEARTBEAT", "VISION_POSITION_ESTIMATE", "ODOMETRY"]
    assert all(m.get_srcSystem() == 1 and m.get_srcComponent() == 191 for m in msgs)
    vpe, odo = msgs[1], msgs[2]
    assert vpe.usec == 2_500_000 and vpe.reset_counter == 2  # 258 mod 256
    assert (vpe.x, vpe.y, vpe.z) == pytest.approx((1.0, -2.0, -1.5))
    assert vpe.covariance[0] == pytest.approx(1e-4) and vpe.covariance[6] == pytest.approx(2e-4)
    assert vpe.covariance[20] == pytest.approx(3e-3)  # yaw variance: the last of the upper triangle
    assert odo.time_usec == 2_600_000 and list(odo.q) == pytest.approx([1, 0, 0, 0])
    assert (odo.vx, odo.vy, odo.vz) == pytest.approx((0.5, 0.0, -0.1)) and math.isnan(odo.pose_covariance[0])


def test_nobody_listening_loses_nothing_on_our_side():
    with MavlinkSink(f"udpout:127.0.0.1:{_free_port()}") as link:
        for k in range(50):
            link.send_vision_position(k / 30, (0.0, 0.0, -1.0), (0.0, 0.0, 0.0))
    assert link.sent["VISION_POSITION_ESTIMATE"] == 50


def test_heartbeat_checks_the_time_first_and_restarts_with_the_clock():
    with MavlinkSink(f"udpout:127.0.0.1:{_free_port()}") as link:
        for bad in (math.nan, -1.0, math.inf):
            with pytest.raises(ValueError, match="time_s"):
                link.send_vision_position(bad, (0.0, 0.0, -1.0), (0.0, 0.0, 0.0))
        assert link.sent == {}  # no beat went out for a time that was refused
        beats = []
        for t in (0.0, 0.5, 1.0, 1.5, 2.2, 0.1, 0.5, 1.05, 1.2):  # a second recording starts at 0.1 s
            link.send_vision_position(t, (0.0, 0.0, -1.0), (0.0, 0.0, 0.0))
            beats.append(link.sent["HEARTBEAT"])
    assert beats == [1, 1, 2, 2, 3, 4, 4, 4, 5]


def test_quaternions_are_scipys_in_mavlinks_order():
    from scipy.spatial.transform import Rotation

    from visloc.io.mavlink import _quaternion

    for R in Rotation.random(500, random_state=2).as_matrix():
        x, y, z, w = Rotation.from_matrix(R).as_quat()
        want = np.array([w, x, y, z]) * (1 if w >= 0 else -1)
        assert np.allclose(_quaternion(R), want, atol=1e-12)


def test_the_down_camera_is_the_simulators_mounting():
    from visloc.io.mavlink import DOWN_CAMERA
    from visloc.sim import BODY_TO_CAMERA

    assert np.array_equal(DOWN_CAMERA, BODY_TO_CAMERA.T)  # one convention: io states it, sim flies it


def test_map_frames_turn_into_ned():
    p = np.array([1.0, 2.0, 3.0])  # 1 m along x, 2 along y, 3 up
    assert MAP_FRAMES["nwu"] @ p == pytest.approx([1.0, -2.0, -3.0])
    assert MAP_FRAMES["enu"] @ p == pytest.approx([2.0, 1.0, -3.0])
    # a downward camera over a nwu map, image top toward north: the body is level, facing north
    R_map_cam = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    assert body_attitude_ned(R_map_cam, map_frame="nwu") == pytest.approx(np.eye(3))
    with pytest.raises(ValueError, match="map_frame"):
        body_attitude_ned(R_map_cam, map_frame="xyz")


def test_localize_sends_every_fix_as_the_csv_says(tmp_path):
    src = tmp_path / "flight"
    assert main(["render", "localize", str(src), "--seconds", "2.2", "--fps", "10", "--seed", "4"]) == 0
    port = _free_port()
    rx = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="common")
    out = tmp_path / "est.csv"
    assert main(["localize", str(src), "--camera", str(src / "camera.yml"), "--map", str(src / "map.yml"),
                 "--out", str(out), "--fps", "10", "--mavlink", f"udpout:127.0.0.1:{port}", "--quiet"]) == 0
    msgs = _receive(rx)
    rx.close()
    rows = list(csv.DictReader(out.open()))
    used = [r for r in rows if r["fix"] == "used"]
    vpe = [m for m in msgs if m.get_type() == "VISION_POSITION_ESTIMATE"]
    beats = [m for m in msgs if m.get_type() == "HEARTBEAT"]
    assert len(used) >= 20 and len(vpe) == len(used)
    assert len(beats) == 3  # one per second of frame time over 0 .. 2.1 s
    F = MAP_FRAMES["nwu"]
    for m, r in zip(vpe, used, strict=True):
        assert m.usec == round(float(r["time"]) * 1e6)
        ned = F @ np.array([float(r["x"]), float(r["y"]), float(r["z"])])
        assert (m.x, m.y, m.z) == pytest.approx(ned, abs=1e-5)  # float32 on the wire
        assert m.covariance[0] == pytest.approx(float(r["std_x"]) ** 2, rel=1e-4)
        assert math.isnan(m.covariance[15])  # attitude variances: unknown
        # the drone of `render localize` flies level-ish: roll and pitch small
        assert abs(m.roll) < 0.3 and abs(m.pitch) < 0.3


def test_missing_pymavlink_is_one_clear_line(tmp_path, monkeypatch, capsys):
    import builtins

    real = builtins.__import__

    def no_pymavlink(name, *a, **k):
        if name.startswith("pymavlink"):
            raise ImportError(name)
        return real(name, *a, **k)

    src = tmp_path / "flight"
    assert main(["render", "localize", str(src), "--seconds", "0.1", "--fps", "10"]) == 0
    monkeypatch.setattr(builtins, "__import__", no_pymavlink)
    code = main(["localize", str(src), "--camera", str(src / "camera.yml"), "--map", str(src / "map.yml"),
                 "--fps", "10", "--mavlink", "--quiet"])
    assert code == 2 and "pip install 'visloc[mavlink]'" in capsys.readouterr().err


def test_track_sends_the_bodys_pose_in_ned(tmp_path):
    from tests.pose.test_relative import write_track_inputs

    truth = write_track_inputs(tmp_path, 5.0, 3)
    frames = tmp_path / "frames"
    port = _free_port()
    rx = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="common")
    out = tmp_path / "track.jsonl"
    assert main(["track", str(frames), "--camera", str(tmp_path / "cam.yml"), "--body", str(tmp_path / "body.yml"),
                 "--reference", str(tmp_path / "ref.yml"), "--fps", "30", "--mavlink", f"udpout:127.0.0.1:{port}",
                 "--map-frame", "enu", "--out", str(out), "--quiet"]) == 0
    vpe = [m for m in _receive(rx) if m.get_type() == "VISION_POSITION_ESTIMATE"]
    rx.close()
    recs = [json.loads(x) for x in out.read_text().splitlines()]
    assert len(vpe) == 3 == len(recs)
    for m, T, r in zip(vpe, truth, recs, strict=True):
        assert (m.x, m.y, m.z) == pytest.approx(MAP_FRAMES["enu"] @ T.t, abs=0.01)  # enu: north = map y
        assert m.usec == round(r["time"] * 1e6)
        # the JSON's angles (map enu, body x forward, y left, z up) in NED/FRD: roll kept, pitch
        # (nose up) of opposite sign, yaw from north clockwise = 90 deg - yaw from east
        roll, pitch, yaw = r["euler_zyx_rad"]
        assert (m.roll, m.pitch, m.yaw) == pytest.approx((roll, -pitch, np.pi / 2 - yaw), abs=1e-5)
        assert yaw == pytest.approx(np.radians(10 + 5 * recs.index(r)), abs=np.radians(0.5))


def test_detect_sends_the_pad_as_landing_target(tmp_path, capsys):
    import cv2

    from visloc.io.mavlink import DOWN_CAMERA
    from visloc.markers import MarkerDetector
    from visloc.pose.maps import MarkerMap

    src = tmp_path / "flight"  # a downward camera over a marker grid: the same ids frame after frame
    assert main(["render", "localize", str(src), "--seconds", "0.4", "--fps", "10", "--seed", "2"]) == 0
    grid = MarkerMap.from_file(src / "map.yml")
    side = float(np.linalg.norm(np.diff(grid.corners_of(int(grid.ids[0]))[:2], axis=0)))
    pad = MarkerDetector("DICT_4X4_100").detect(cv2.imread(str(min(src.glob("frame_*.png")))))[0].id
    port = _free_port()
    rx = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="common")
    out = tmp_path / "det.jsonl"
    base = ["detect", str(src), "--dict", "DICT_4X4_100", "--camera", str(src / "camera.yml"), "--marker-length",
            f"{side}", "--fps", "10"]
    assert main([*base, "--out", str(out), "--mavlink", f"udpout:127.0.0.1:{port}", "--target-id", str(pad),
                 "--quiet"]) == 0
    msgs = [m for m in _receive(rx) if m.get_type() == "LANDING_TARGET"]
    rx.close()
    frames = [json.loads(x) for x in out.read_text().splitlines()]
    views = [(f, next(m for m in f["markers"] if m["id"] == pad)) for f in frames
             if any(m["id"] == pad for m in f["markers"])]
    assert len(views) >= 2 and len(msgs) == len(views)
    for msg, (f, m) in zip(msgs, views, strict=True):
        t = np.array(m["tvec"])
        assert msg.time_usec == round(f["time"] * 1e6) and msg.target_num == pad and msg.position_valid == 1
        assert msg.angle_x == pytest.approx(np.arctan2(t[0], t[2]), abs=1e-5)
        assert msg.angle_y == pytest.approx(np.arctan2(t[1], t[2]), abs=1e-5)
        assert msg.distance == pytest.approx(np.linalg.norm(t), rel=1e-5)
        assert (msg.x, msg.y, msg.z) == pytest.approx(DOWN_CAMERA @ t, abs=1e-5)
        assert msg.size_x == pytest.approx(2 * np.arctan(side / 2 / np.linalg.norm(t)), rel=1e-4)
    assert main([*base, "--mavlink"]) == 2  # which marker is the pad?
    assert "--target-id" in capsys.readouterr().err


def test_flow_sends_each_pair_as_optical_flow_rad(tmp_path):
    src = tmp_path / "ground"
    assert main(["render", "flow", str(src), "--seconds", "0.3", "--fps", "30", "--seed", "3"]) == 0
    port = _free_port()
    rx = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="common")
    out = tmp_path / "v.csv"
    assert main(["flow", str(src), "--fps", "30", "--camera", str(src / "camera.yml"), "--height-csv",
                 str(src / "heights.csv"), "--out", str(out), "--mavlink", f"udpout:127.0.0.1:{port}", "--quiet"]) == 0
    flows = [m for m in _receive(rx) if m.get_type() == "OPTICAL_FLOW_RAD"]
    rx.close()
    rows = list(csv.DictReader(out.open()))[1:]  # the first frame has no pair
    heights = {int(r["frame"]): float(r["height"]) for r in csv.DictReader((src / "heights.csv").open())}
    assert len(flows) == len(rows) >= 8
    for m, r in zip(flows, rows, strict=True):
        dt, h = 1 / 30, heights[int(r["frame"])]
        assert m.time_usec == round(float(r["time"]) * 1e6) and m.integration_time_us == round(dt * 1e6)
        # moving along +x: positive flow about y; along +y: negative flow about x
        assert m.integrated_y == pytest.approx(float(r["vx"]) * dt / h, rel=1e-5, abs=1e-9)
        assert m.integrated_x == pytest.approx(-float(r["vy"]) * dt / h, rel=1e-5, abs=1e-9)
        assert m.quality == round(255 * float(r["quality"])) and m.distance == pytest.approx(h, rel=1e-6)
        assert math.isnan(m.integrated_xgyro)


def test_flow_with_an_imu_sends_the_gyro_integrals_and_the_rotation_back_in_the_flow(tmp_path):
    src = tmp_path / "ground"
    assert main(["render", "flow", str(src), "--seconds", "0.2", "--fps", "30", "--seed", "5"]) == 0
    rates = np.array([0.02, -0.01, 0.3])  # rad/s in camera axes, constant
    t = np.arange(0, 0.5, 0.005)
    imu = tmp_path / "imu.csv"
    np.savetxt(imu, np.column_stack([t, np.tile(rates, (len(t), 1)), np.zeros((len(t), 3))]), delimiter=",",
               header="t,gx,gy,gz,fx,fy,fz", comments="", fmt="%.6g")
    port = _free_port()
    rx = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="common")
    out = tmp_path / "v.csv"
    assert main(["flow", str(src), "--fps", "30", "--camera", str(src / "camera.yml"), "--height-csv",
                 str(src / "heights.csv"), "--imu", str(imu), "--out", str(out), "--mavlink",
                 f"udpout:127.0.0.1:{port}", "--quiet"]) == 0
    flows = [m for m in _receive(rx) if m.get_type() == "OPTICAL_FLOW_RAD"]
    rx.close()
    rows = list(csv.DictReader(out.open()))[1:]
    heights = {int(r["frame"]): float(r["height"]) for r in csv.DictReader((src / "heights.csv").open())}
    assert len(flows) == len(rows) >= 5
    dt = 1 / 30
    for m, r in zip(flows, rows, strict=True):
        h = heights[int(r["frame"])]
        w = rates * dt
        assert (m.integrated_xgyro, m.integrated_ygyro, m.integrated_zgyro) == pytest.approx(w, rel=1e-5)
        # the CSV's velocity has the roll and pitch rotation removed; the message puts it back
        assert m.integrated_x == pytest.approx(-float(r["vy"]) * dt / h + w[0], rel=1e-5, abs=1e-8)
        assert m.integrated_y == pytest.approx(float(r["vx"]) * dt / h + w[1], rel=1e-5, abs=1e-8)


def test_odometry_of_a_nan_quality_is_invalid_and_a_bad_call_sends_nothing():
    # min(100, nan) sent a NaN quality as 100; a bad attitude raised after the heartbeat went out
    port = _free_port()
    rx = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="common")
    with MavlinkSink(f"udpout:127.0.0.1:{port}") as link:
        with pytest.raises(IndexError):
            link.send_odometry(1.0, (0.0, 0.0, -1.0), np.eye(2), (0.0, 0.0, 0.0))
        assert link.sent == {}
        link.send_odometry(1.0, (0.0, 0.0, -1.0), np.eye(3), (0.0, 0.0, 0.0), quality=math.nan)
        link.send_odometry(1.1, (0.0, 0.0, -1.0), np.eye(3), (0.0, 0.0, 0.0), quality=150)
    odo = [m for m in _receive(rx) if m.get_type() == "ODOMETRY"]
    rx.close()
    assert [m.quality for m in odo] == [0, 100]


def test_a_jump_of_the_frame_clock_costs_one_beat_not_a_loop_per_period():
    # the schedule used to be caught up one period at a time: minutes for epoch seconds,
    # for ever beyond 2^53 s
    import time

    with MavlinkSink(f"udpout:127.0.0.1:{_free_port()}") as link:
        start = time.perf_counter()
        for t in (0.0, 1.0, 1.7e9, 1.7e9 + 0.5, 1.7e9 + 1.0, 1e20):
            link.heartbeat(t)
        assert time.perf_counter() - start < 1.0
        assert link.sent["HEARTBEAT"] == 5  # 0, 1, 1.7e9, 1.7e9 + 1 and 1e20
