"""Every reader on real files (excerpts shipped in tests/data and the package examples)."""

import json
import math

import numpy as np
import pytest

from mbicp_viz.core import Pose2, pose_error
from mbicp_viz.errors import InputError
from mbicp_viz.readers import ReadOptions, read_log
from mbicp_viz.readers.plain import read_npz, write_npz

from .conftest import DATA, HOKUYO_BAG


def test_carmen_flaser_intel(intel):
    assert len(intel) == 60 and intel.skipped == {}  # NEFF lines were cut from the excerpt
    s = intel.scans[0]
    assert len(s.ranges) == 180 and s.n_valid > 100
    # 180 readings: a SICK at 1 degree without its last beam (CARMEN's readlog.c)
    assert s.bearings[0] == pytest.approx(-math.pi / 2) and s.bearings[-1] == pytest.approx(
        math.radians(89.0)
    )
    assert s.pose == s.odometry and s.pose.x == pytest.approx(0.600266)
    assert s.source.line is not None and s.stamp == pytest.approx(32.9068)
    assert len(intel.odometry) > 100  # ODOM lines
    # no-return codes are masked, never points
    assert not np.any((s.ranges[s.valid] > 81.8) & (s.ranges[s.valid] < 82.0))


def test_carmen_aces_gz_masks_its_no_return_code():
    log = read_log(DATA / "aces-10.log.gz")
    assert len(log) == 10
    all_r = np.concatenate([s.ranges for s in log.scans])
    all_v = np.concatenate([s.valid for s in log.scans])
    assert np.any(np.isclose(all_r, 50.0))  # the file has them...
    assert not np.any(np.isclose(all_r[all_v], 50.0))  # ...and they are masked


def test_carmen_361_beams_with_nan():
    log = read_log(DATA / "laserazosSM3-40.log")
    s = log.scans[0]
    assert len(log) == 40 and len(s.ranges) == 361
    assert s.bearings[1] - s.bearings[0] == pytest.approx(math.radians(0.5))
    assert np.all(np.isfinite(s.points()))


def test_off_block_layout_matches_carmen_conversion():
    off = read_log(DATA / "laserazosSM3-6.off")
    log = read_log(DATA / "laserazosSM3-40.log")
    assert len(off) == 6
    for a, b in zip(off.scans, log.scans):
        np.testing.assert_array_equal(a.valid, b.valid)
        np.testing.assert_allclose(a.ranges[a.valid], b.ranges[b.valid])
        assert a.odometry.as_array() == pytest.approx(b.odometry.as_array(), abs=1e-6)


def test_off_one_scan_per_line():
    log = read_log(DATA / "datos.off")
    assert len(log) == 2 and len(log.scans[0].ranges) == 361


def test_csm_json_full_circle():
    log = read_log(DATA / "stallo2.jsonl")
    s = log.scans[0]
    assert len(log) == 2 and len(s.ranges) == 1024
    assert s.is_full_circle()
    assert s.odometry is not None and s.pose is None  # estimate and true_pose are null


def test_ros1_bag_with_damaged_index_is_recovered(hokuyo):
    from rosbags.highlevel import AnyReader

    with pytest.raises(Exception):  # noqa: B017 - rosbags itself refuses this bag, with its own types
        with AnyReader([HOKUYO_BAG]) as r:
            list(r.messages())
    assert len(hokuyo) == 360
    s = hokuyo.scans[0]
    assert len(s.ranges) == 681 and s.n_valid > 500
    assert s.bearings[-1] - s.bearings[0] == pytest.approx(math.radians(239), abs=0.01)
    assert np.all(s.ranges[s.valid] < 5.6)
    stamps = [x.stamp for x in hokuyo.scans]
    assert np.all(np.diff(stamps) > 0)


def _write_bag(path, scans, version):
    """Write real scans into a bag with rosbags' own writer (ROS 1 or ROS 2)."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if version == 1 else Stores.ROS2_HUMBLE)
    LaserScan = store.types["sensor_msgs/msg/LaserScan"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]

    def msg(s, k):
        sec = int(s.stamp)
        head = (
            Header(seq=k, stamp=Time(sec=sec, nanosec=int((s.stamp - sec) * 1e9)), frame_id="laser")
            if version == 1
            else Header(stamp=Time(sec=sec, nanosec=int((s.stamp - sec) * 1e9)), frame_id="laser")
        )
        inc = float(s.bearings[1] - s.bearings[0])
        return LaserScan(
            header=head,
            angle_min=float(s.bearings[0]),
            angle_max=float(s.bearings[-1]),
            angle_increment=inc,
            time_increment=0.0,
            scan_time=0.1,
            range_min=0.02,
            range_max=5.6,
            ranges=np.where(s.valid, s.ranges, 0.0).astype(np.float32),
            intensities=np.zeros(0, np.float32),
        )

    if version == 1:
        from rosbags.rosbag1 import Writer

        with Writer(path) as w:
            conn = w.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=store)
            for k, s in enumerate(scans):
                w.write(
                    conn,
                    int(s.stamp * 1e9),
                    store.serialize_ros1(msg(s, k), "sensor_msgs/msg/LaserScan"),
                )
    else:
        from rosbags.rosbag2 import Writer

        with Writer(path, version=8) as w:
            conn = w.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=store)
            for k, s in enumerate(scans):
                w.write(
                    conn,
                    int(s.stamp * 1e9),
                    store.serialize_cdr(msg(s, k), "sensor_msgs/msg/LaserScan"),
                )


@pytest.mark.parametrize("version", [1, 2])
def test_ros_bags_written_by_rosbags_round_trip(tmp_path, hokuyo, version):
    scans = hokuyo.scans[:5]
    path = tmp_path / ("scans.bag" if version == 1 else "scans_ros2")
    _write_bag(path, scans, version)
    log = read_log(path)
    assert len(log) == 5
    for a, b in zip(log.scans, scans):
        np.testing.assert_array_equal(a.valid, b.valid)
        np.testing.assert_allclose(a.ranges[a.valid], b.ranges[b.valid], rtol=1e-6)
        np.testing.assert_allclose(a.bearings, b.bearings, atol=1e-6)


def test_plain_text_and_npz_round_trip(tmp_path, intel):
    scans = intel.scans[:3]
    txt = tmp_path / "pair.scans"
    lines = ["# mbicp-viz scans v1: angle_min_rad angle_increment_rad range_1_m ..."]
    for s in scans:
        r = np.where(s.valid, s.ranges, np.nan)
        lines.append(
            " ".join(
                [repr(float(s.bearings[0])), repr(float(s.bearings[1] - s.bearings[0]))]
                + [repr(float(v)) for v in r]
            )
        )
    txt.write_text("\n".join(lines) + "\n")
    npz = tmp_path / "pair.npz"
    write_npz(npz, scans)
    for log in (read_log(txt), read_npz(str(npz))):
        assert len(log) == 3
        for a, b in zip(log.scans, scans):
            np.testing.assert_array_equal(a.valid, b.valid)
            np.testing.assert_allclose(a.points(), b.points(), atol=1e-9)
    assert read_npz(str(npz)).scans[1].pose == scans[1].pose


def rawlaser_head(s) -> str:
    """A RAWLASER/ROBOTLASER1 line's fields up to its ranges, for scan ``s``'s own bearings."""
    n = len(s.ranges)
    step = s.angular_span() / (n - 1)
    return f"0 {float(s.bearings[0])!r} {s.angular_span()!r} {step!r} 81.9 0.01 0 {n}"


def test_rawlaser_and_robotlaser_lines_read_like_flaser(tmp_path, intel):
    """No shared log has RAWLASER/ROBOTLASER lines: write real Intel scans in those formats."""
    lines_raw, lines_robot = [], []
    for s in intel.scans[:3]:
        head = f"{rawlaser_head(s)} " + " ".join(str(float(v)) for v in s.ranges)
        lines_raw.append(f"RAWLASER1 {head} 0 {s.stamp} host {s.stamp}")
        p, o = s.pose, s.odometry
        lines_robot.append(
            f"ROBOTLASER1 {head} 0 {p.x} {p.y} {p.theta} {o.x} {o.y} {o.theta} 0 0 0 0 0 "
            f"{s.stamp} host {s.stamp}"
        )
    for name, lines in (("raw.log", lines_raw), ("robot.log", lines_robot)):
        path = tmp_path / name
        path.write_text("\n".join(lines) + "\n")
        log = read_log(path)
        assert len(log) == 3
        for a, b in zip(log.scans, intel.scans[:3]):
            np.testing.assert_array_equal(a.valid, b.valid)
            np.testing.assert_allclose(a.points(), b.points(), atol=1e-9)
            assert a.stamp == pytest.approx(b.stamp)
        if name == "robot.log":
            assert log.scans[1].pose.as_array() == pytest.approx(intel.scans[1].pose.as_array())


def two_lasers(path, intel, n_scans=4):
    """A CARMEN log of Intel's scans 0.. as FLASER and RAWLASER1 at the same instants (one laser,
    logged twice) and its scans 10.. as RAWLASER2 (another laser), interleaved as a logger writes
    them."""
    lines = []
    for k, s in enumerate(intel.scans[:n_scans]):
        n, ranges = len(s.ranges), " ".join(str(float(v)) for v in s.ranges)
        p, o = s.pose, s.odometry
        other = " ".join(str(float(v)) for v in intel.scans[10 + k].ranges)
        head = rawlaser_head(s)
        lines += [
            f"FLASER {n} {ranges} {p.x} {p.y} {p.theta} {o.x} {o.y} {o.theta} {s.stamp} host "
            f"{s.stamp}",
            f"RAWLASER1 {head} {ranges} 0 {s.stamp} host {s.stamp}",
            f"RAWLASER2 {head} {other} 0 {s.stamp} host {s.stamp}",
        ]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_log_with_several_laser_message_types_is_read_one_type_at_a_time(tmp_path, intel):
    """A pair across two laser message types is no motion: a log with several is read one type at a
    time, named like a bag's topic; unnamed, the front laser with its poses, and a note says so."""
    path = two_lasers(tmp_path / "two-lasers.log", intel)
    log = read_log(path)
    assert log.topic == "FLASER" and np.allclose(
        log.scans[1].pose.as_array(), intel.scans[1].pose.as_array()
    )
    assert log.notes == [
        f"{path}: read FLASER (4 scans), the front laser with its poses; the log also has "
        "RAWLASER1 "
        "(4 scans); RAWLASER2 (4 scans): --topic (in the debugger: scan stream) reads another"
    ]
    path.write_text("PARAM robot_frontlaser_offset 0.2 host 0\n" + path.read_text())
    for kind, first in (("FLASER", 0), ("RAWLASER1", 0), ("RAWLASER2", 10)):
        log = read_log(path, ReadOptions(topic=kind))
        assert (
            len(log) == 4
            and log.topic == kind
            and list(log.scan_topics) == ["FLASER", "RAWLASER1", "RAWLASER2"]
        )
        # the front laser's mount is laser 1's, not laser 2's
        assert (log.frames.mount_source == "PARAM robot_frontlaser_offset") == (kind != "RAWLASER2")
        for a, b in zip(log.scans, intel.scans[first : first + 4]):
            np.testing.assert_allclose(a.points(), b.points(), atol=1e-9)
    with pytest.raises(InputError, match="no 'ROBOTLASER1' scans; the log has: FLASER"):
        read_log(path, ReadOptions(topic="ROBOTLASER1"))
    assert read_log(DATA / "laserazosSM3-40.log").topic is None  # one type: nothing to choose
    assert read_log(path, ReadOptions(topic="RAWLASER2")).notes == []  # named: nothing to say
    # a front laser logged raw beside another laser: the front one; no front laser: nothing to
    # prefer
    rear = tmp_path / "rear.log"
    rear.write_text(
        "".join(
            line + "\n" for line in path.read_text().splitlines() if not line.startswith("FLASER")
        )
    )
    assert read_log(rear).topic == "RAWLASER1"
    rear.write_text(rear.read_text().replace("RAWLASER1 ", "RAWLASER3 "))
    with pytest.raises(InputError) as e:
        read_log(rear)
    assert e.value.field == "--topic"
    assert (
        "2 laser message types, choose one with --topic: RAWLASER3 (4 scans); RAWLASER2 (4 scans)"
        in str(e.value)
    )

    from mbicp_viz.views.debugger.sources import files_source
    from mbicp_viz.views.debugger.state import DebugState

    state = DebugState(
        files_source(str(path), None, guess="identity", options=ReadOptions(topic="FLASER"))
    )
    assert state.rematch() is None and state.set_topic("RAWLASER2") is None  # the debugger's picker
    assert state.pair == (0, 1) and np.allclose(
        state.ref.points(), intel.scans[10].points(), atol=1e-9
    )


def flaser_log(path, n: int, params: str = "", scans: int = 2):
    """A FLASER log of ``n`` readings a line (ranges of a room, 2-5 m)."""
    ranges = " ".join(f"{2.0 + 3.0 * abs(math.sin(0.05 * k)):.2f}" for k in range(n))
    path.write_text(
        params + "".join(f"FLASER {n} {ranges} 0 0 0 0 0 0 {t} host {t}\n" for t in range(scans))
    )
    return path


@pytest.mark.parametrize(
    "n, start_deg, step_deg, noted",
    [
        (361, -90, 0.5, False),
        (360, -90, 0.5, False),  # the SICK's 361 without its last beam (CARMEN: 179.5 degrees)
        (181, -90, 1.0, False),
        (180, -90, 1.0, False),
        (401, -50, 0.25, False),
        (400, -50, 0.25, False),
        (682, -90, 180 / 681, True),
    ],
)
def test_flaser_bearings_follow_the_beam_count_as_carmen_guesses_them(
    tmp_path, n, start_deg, step_deg, noted
):
    """FLASER stores no field of view: a SICK's counts step as CARMEN's readlog.c guesses (1, 0.5,
    0.25 degrees: 180 and 360 readings lack the SICK's last beam); any other count is read over
    180 degrees, as CSM does, and said so."""
    log = read_log(flaser_log(tmp_path / "f.log", n))
    b = np.degrees(log.scans[0].bearings)
    assert b[0] == pytest.approx(start_deg) and np.diff(b) == pytest.approx(step_deg)
    assert (
        any("FLASER stores no field of view" in note and str(n) in note for note in log.notes)
        == noted
    )


def test_flaser_bearings_and_maximum_range_follow_the_logs_own_params(tmp_path):
    """CARMEN's PARAM lines state the front laser's step and maximum range: 360 readings at 0.5
    degrees span 179.5 degrees, and a reading at or beyond the maximum is no return."""
    params = (
        "PARAM laser_front_laser_resolution 0.5 nohost 0\n"
        "PARAM robot_front_laser_max 4.0 nohost 0\n"
    )
    log = read_log(flaser_log(tmp_path / "p.log", 360, params))
    s = log.scans[0]
    assert np.degrees(s.bearings[-1] - s.bearings[0]) == pytest.approx(179.5)
    assert np.all(s.ranges[s.valid] < 4.0) and np.any(s.ranges >= 4.0) and log.notes == []
    # a step that cannot hold the readings within 180 degrees is said, and the SICK's is used
    log = read_log(
        flaser_log(tmp_path / "q.log", 361, "PARAM laser_front_laser_resolution 1 nohost 0\n")
    )
    assert np.degrees(np.diff(log.scans[0].bearings)) == pytest.approx(0.5)
    assert any("cannot hold 361 readings" in note for note in log.notes)


def _recoded(intel_path, out, code):
    """The Intel excerpt with its SICK no-return code (81.83 m) rewritten by ``code(k)``."""
    import gzip

    lines, k = [], 0
    for line in gzip.open(intel_path, "rt"):
        t = line.split()
        if t and t[0] == "FLASER":
            for i in range(2, 2 + int(t[1])):
                if t[i] == "81.83":
                    t[i], k = code(k), k + 1
            line = " ".join(t) + "\n"
        lines.append(line)
    out.write_text("".join(lines))
    return out


@pytest.mark.parametrize(
    "code, said",
    [
        (lambda k: f"{51.0 + 0.01 * (k % 31):.2f}", "readings of 51.00-51.30 m"),
        (lambda k: "32.76", "readings of 32.76 m"),
    ],
)
def test_a_logs_own_no_return_code_is_found_and_masked(tmp_path, code, said):
    """A log that states no maximum range writes its own code for no return (51.0-51.3 m, 32.76 m in
    field logs): a spike at the top of its readings, masked and said, never a wall of points."""
    from .conftest import INTEL

    log = read_log(_recoded(INTEL, tmp_path / "coded.log", code))
    assert any(said in note and "no-return code" in note for note in log.notes), log.notes
    top = max(s.ranges[s.valid].max() for s in log.scans)
    assert top < 30.0  # only the excerpt's real readings are left
    assert sum(s.n_valid for s in log.scans) == sum(s.n_valid for s in read_log(INTEL).scans)


def test_real_readings_at_fifty_metres_are_kept_in_a_long_range_log(tmp_path, intel):
    """The aces log's 50.00 m is its code, not everyone's: in a log of real readings out to 60 m
    (the Intel excerpt's room, scaled so that its commonest far reading lands on 50.00 m), the
    readings on 50.00 m stay."""
    import gzip

    from .conftest import INTEL

    far = np.concatenate([s.ranges[s.valid] for s in intel.scans])
    values, counts = np.unique(far[(far > 15.0) & (far < 22.0)], return_counts=True)
    scale = 50.0 / values[np.argmax(counts)]
    out = []
    for line in gzip.open(INTEL, "rt"):
        t = line.split()
        if t and t[0] == "FLASER":
            n = int(t[1])
            t[2 : 2 + n] = [v if v == "81.83" else f"{scale * float(v):.2f}" for v in t[2 : 2 + n]]
            line = " ".join(t) + "\n"
        out.append(line)
    scaled = tmp_path / "large.log"
    scaled.write_text("".join(out))
    log = read_log(scaled)
    readings = np.concatenate([s.ranges[s.valid] for s in log.scans])
    assert np.count_nonzero(np.isclose(readings, 50.0, atol=0.005)) == counts.max()
    assert readings.max() > 50.0 and not any("no-return code" in note for note in log.notes)


def test_carmen_laser_poses_are_the_lasers_and_odometry_moves_onto_the_laser(tmp_path, intel):
    """FLASER's x y theta is the laser's pose (the offset is in it), its odom_* the robot's; a
    ROBOTLASER1 line's laser and robot poses imply the mount."""
    offset, mount = Pose2(0.2, 0.0, 0.0), Pose2(0.2, 0.05, 0.1)
    flaser, robot = ["PARAM robot_frontlaser_offset 0.2 host 0"], []
    for s in intel.scans[:3]:
        n, ranges = len(s.ranges), " ".join(str(float(v)) for v in s.ranges)
        base = s.odometry  # the robot's odometry
        p = base @ offset  # what CARMEN's logger writes as the laser's pose
        flaser.append(
            f"FLASER {n} {ranges} {p.x!r} {p.y!r} {p.theta!r} {base.x!r} {base.y!r} "
            f"{base.theta!r} {s.stamp} host {s.stamp}"
        )
        q = base @ mount
        head = f"{rawlaser_head(s)} {ranges}"
        robot.append(
            f"ROBOTLASER1 {head} 0 {q.x!r} {q.y!r} {q.theta!r} {base.x!r} {base.y!r} "
            f"{base.theta!r} 0 0 0 0 0 {s.stamp} host {s.stamp}"
        )
    (tmp_path / "f.log").write_text("\n".join(flaser) + "\n")
    (tmp_path / "r.log").write_text("\n".join(robot) + "\n")
    f, r = read_log(tmp_path / "f.log"), read_log(tmp_path / "r.log")
    for k, s in enumerate(intel.scans[:3]):
        laser = s.odometry @ offset
        assert pose_error(f.scans[k].pose, laser)[0] < 1e-9  # not the offset twice
        assert pose_error(f.scans[k].odometry, laser)[0] < 1e-9
        assert pose_error(r.scans[k].odometry, s.odometry @ mount)[0] < 1e-9
    assert r.frames.mount_source == "ROBOTLASER1 laser_pose against robot_pose"
    assert np.abs((r.frames.mount.inverse() @ mount).as_array()).max() < 1e-9


def test_a_csm_log_with_uneven_bearings_skips_those_scans_and_counts_them(tmp_path):
    """CSM's JSON of MIT CSAIL's data: some scans have two bearings under 1e-4 rad apart. Those
    are skipped and counted; the file was refused whole."""
    one = json.loads((DATA / "stallo2.jsonl").read_text().splitlines()[0])
    real = [json.loads(json.dumps(one)) for _ in range(6)]  # a real scan, six times
    for k in (1, 4):
        th = real[k]["theta"]
        th[10] = th[9] + 5e-5
    path = tmp_path / "uneven.jsonl"
    path.write_text("".join(json.dumps(o) + "\n" for o in real))
    log = read_log(path)
    assert len(log.scans) == 4 and sorted(log.unusable) == [1, 4]
    assert "below the finest scanner's step" in log.unusable[1].reason
