"""ROS bags as robots record them, written with rosbags' writers from real Intel and CSM scans:
ROS 1, ROS 2 as Humble's recorder writes it (no message definitions), MCAP; the laser's mount in
/tf_static (rotated, upside down); odometry on /odom and on /tf; several scanners; 360-degree
lidars; beam counts that vary; an empty scan."""

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.core import Pose2, make_scan, pose_error, relative
from mbicp_viz.errors import InputError
from mbicp_viz.readers import ReadOptions, read_log

from .bags import Robot, Topic, intel_robot, write
from .conftest import DATA, json_lines

MOUNT = Pose2(0.25, -0.1, math.pi)  # a laser looking backwards, like a Neato's


def same_scan(a, b) -> bool:
    return (
        np.allclose(a.bearings, b.bearings, atol=1e-6)
        and np.array_equal(a.valid, b.valid)
        and np.allclose(a.ranges[a.valid], b.ranges[b.valid], atol=1e-5)
    )


@pytest.mark.parametrize("kind", ["ros1", "humble", "mcap"])
@pytest.mark.parametrize("upside_down", [False, True])
def test_bags_of_every_kind_read_their_scans_mount_and_odometry(tmp_path, intel, kind, upside_down):
    path = write(
        tmp_path / ("r.bag" if kind == "ros1" else "r"),
        intel_robot(intel, 10, 6, MOUNT, upside_down),
        kind,
    )
    log = read_log(path)
    assert len(log.scans) == 6 and log.topic == "/scan" and log.frames.frame_id == "laser"
    for k, s in enumerate(log.scans):  # the scans the robot's laser saw, upright
        assert same_scan(s, intel.scan(10 + k))
        assert pose_error(s.odometry, intel.scan(10 + k).pose)[0] < 1e-9  # the laser's pose in odom
    m = log.frames.mount
    assert (m.x, m.y, m.theta) == pytest.approx((MOUNT.x, MOUNT.y, MOUNT.theta), abs=1e-9)
    assert (
        log.frames.mount_source == "tf base_link -> laser" and log.frames.base_frame == "base_link"
    )


def test_a_humble_bag_needs_a_typestore_and_a_wrong_one_is_named(tmp_path, intel):
    path = write(tmp_path / "h", intel_robot(intel, 10, 3, None), "humble")
    assert len(read_log(path, ReadOptions(typestore="ROS2_FOXY")).scans) == 3
    with pytest.raises(InputError, match="unknown ROS distro 'ROS2_NOPE'"):
        read_log(path, ReadOptions(typestore="ROS2_NOPE"))


def test_matches_answer_in_the_base_frame_and_agree_with_the_odometry(tmp_path, intel):
    path = write(tmp_path / "r.bag", intel_robot(intel, 10, 8, MOUNT), "ros1")
    out = tmp_path / "rows.json"
    res = CliRunner().invoke(
        app,
        ["eval", "sequence", str(path), "--guess", "odometry", "--out", str(out), "--workers", "1"],
    )
    assert res.exit_code == 0, res.output
    rows = json_lines(out)
    assert all(r["frame"] == "base_link" for r in rows)
    assert "against the odometry: 7/7 within 5 cm and 1 deg" in res.output
    assert "motions of the robot's base_link" in res.output
    for r in rows:  # the base's motion: the laser's (the log's poses) seen through the mount
        laser = relative(intel.scan(10 + r["ref"]).pose, intel.scan(10 + r["obj"]).pose)
        base = MOUNT.conjugate(laser)
        assert pose_error(Pose2(r["x"], r["y"], r["theta"]), base)[0] < 0.05
    laser_rows = tmp_path / "laser.json"
    res = CliRunner().invoke(
        app,
        [
            "eval",
            "sequence",
            str(path),
            "--guess",
            "odometry",
            "--out",
            str(laser_rows),
            "--frame",
            "laser",
            "--workers",
            "1",
            "--limit",
            "1",
        ],
    )
    first = json_lines(laser_rows)[0]
    assert first["frame"] == "laser"
    assert (
        pose_error(
            MOUNT.conjugate(Pose2(first["x"], first["y"], first["theta"])),
            Pose2(rows[0]["x"], rows[0]["y"], rows[0]["theta"]),
        )[0]
        < 1e-9
    )


def test_odometry_on_tf_and_a_mount_published_on_tf(tmp_path, intel):
    robot = intel_robot(intel, 20, 5, Pose2(0.1, 0.05, 0.3), odometry_on="/tf", mount_on="/tf")
    log = read_log(write(tmp_path / "tf", robot, "mcap"))
    assert (
        log.odometry_source == "tf odom -> base_link"
        and log.frames.mount_source == "tf base_link -> laser"
    )
    assert all(
        pose_error(s.odometry, intel.scan(20 + k).pose)[0] < 1e-9 for k, s in enumerate(log.scans)
    )


def test_two_scanners_are_never_merged(tmp_path, intel, laserazos):
    robot = Robot(
        [
            Topic("/front/scan", "front_laser", [intel.scan(k) for k in range(4)]),
            Topic("/rear/scan", "rear_laser", [laserazos.scan(k) for k in range(4)]),
        ],
        [1.0, 1.2, 1.4, 1.6],
    )
    path = write(tmp_path / "two.bag", robot, "ros1")
    with pytest.raises(InputError) as e:
        read_log(path)
    assert "2 LaserScan topics" in str(e.value) and "--topic" in str(e.value)
    assert "/front/scan (4 messages, frame_id 'front_laser')" in str(e.value)
    assert "/rear/scan (4 messages, frame_id 'rear_laser')" in str(e.value)
    rear = read_log(path, ReadOptions(topic="/rear/scan"))
    assert rear.frames.frame_id == "rear_laser" and all(
        same_scan(s, laserazos.scan(k)) for k, s in enumerate(rear.scans)
    )
    res = CliRunner().invoke(app, ["match", str(path), "--pair", "0", "1", "--topic", "/nope"])
    assert res.exit_code == 2 and "no LaserScan topic '/nope'" in res.output


def stallo(k: int):
    return read_log(DATA / "stallo2.jsonl").scan(k)


def test_a_360_degree_lidar_whose_span_rounds_past_a_full_turn(tmp_path):
    """1147 beams over 360.0003 degrees (a real 360-degree scan resampled): the closing beam repeats
    the first and is dropped; the scan matches its neighbour."""
    scans = []
    for k in (0, 1):
        s = stallo(k)
        b = -math.pi + np.arange(1147) * math.radians(360.0003) / 1146
        r = np.interp(
            b,
            s.bearings[s.valid] - 2 * math.pi * (s.bearings[s.valid] > math.pi),
            s.ranges[s.valid],
            period=2 * math.pi,
        )
        scans.append(make_scan(r, b))
    robot = Robot(
        [Topic("/scan", "laser", scans, increments=[math.radians(360.0003) / 1146] * 2)], [1.0, 1.1]
    )
    log = read_log(write(tmp_path / "l360.bag", robot, "ros1"))
    assert [len(s.bearings) for s in log.scans] == [1146, 1146]
    assert log.scans[0].is_full_circle() and log.scans[0].angular_span() < 2 * math.pi
    res = CliRunner().invoke(
        app, ["match", str(tmp_path / "l360.bag"), "--pair", "0", "1", "--json", "--algo", "psm"]
    )
    assert res.exit_code == 0 and json.loads(res.output)["converged"], res.output


def test_beam_counts_that_vary_keep_their_own_bearings(tmp_path):
    """An RPLidar-like log: every scan has its own number of beams over 360 degrees."""
    base = [stallo(0), stallo(1), stallo(0)]
    keep = [slice(None), slice(0, None, 2), slice(1, None, 3)]
    scans = [make_scan(s.ranges[k], s.bearings[k]) for s, k in zip(base, keep)]
    incs = [float(np.median(np.diff(s.bearings))) for s in scans]
    log = read_log(
        write(
            tmp_path / "rp.bag",
            Robot([Topic("/scan", "laser", scans, increments=incs)], [1, 2, 3]),
            "ros1",
        )
    )
    assert (
        [len(s.bearings) for s in log.scans] == [len(s.bearings) for s in scans] == [1024, 512, 341]
    )
    for name in ("improved", "psm"):  # a coarse reference or a coarse object: every matcher copes
        res = CliRunner().invoke(
            app, ["match", str(tmp_path / "rp.bag"), "--pair", "0", "2", "--algo", name, "--json"]
        )
        assert res.exit_code == 0 and json.loads(res.output)["converged"], (name, res.output)


def test_an_empty_scan_is_skipped_counted_and_refused_only_when_asked_for(tmp_path, intel):
    scans = [intel.scan(k) for k in range(5)]
    empty = make_scan(
        np.full(180, 81.9), scans[2].bearings, valid=np.ones(180, bool), invalid_values=()
    )
    scans[2] = empty  # every reading a no-return code: written as 81.9 m, beyond range_max
    path = write(
        tmp_path / "e.bag", Robot([Topic("/scan", "laser", scans)], [1, 2, 3, 4, 5]), "ros1"
    )
    log = read_log(path)
    assert len(log.scans) == 4 and list(log.unusable) == [2] and log.records == 5
    assert log.consecutive_pairs() == [(0, 1), (1, 3), (3, 4)]
    assert "skipped 1 unusable scan(s) of 5 (first: scan 2" in log.unusable_summary()
    res = CliRunner().invoke(app, ["match", str(path), "--pair", "2", "3"])
    assert res.exit_code == 2 and "scan 2 cannot be matched: no valid reading" in res.output


def test_mount_for_files_without_tf(tmp_path, intel):
    path = write(tmp_path / "plain.bag", intel_robot(intel, 10, 3, None, upside_down=True), "ros1")
    as_written = read_log(path)
    assert as_written.frames.mount_source is None and not same_scan(
        as_written.scans[0], intel.scan(10)
    )
    # the user says how the laser sits
    log = read_log(path, ReadOptions(mount=MOUNT, upside_down=True))
    assert same_scan(log.scans[0], intel.scan(10)) and log.frames.mount == MOUNT
    res = CliRunner().invoke(
        app,
        [
            "match",
            str(path),
            "--pair",
            "0",
            "1",
            "--mount",
            "0.25",
            "-0.1",
            "180",
            "--upside-down",
            "--init",
            "0.6",
            "0",
            "6",
        ],
    )
    assert (
        res.exit_code == 0
        and "motion of the robot's base (laser mount (0.25 m, -0.1 m, 180 deg) from --mount"
        in res.output
    ), res.output


def test_a_bag_cut_short_keeps_its_intact_chunks_and_says_what_was_lost(tmp_path, intel):
    path = write(tmp_path / "r.bag", intel_robot(intel, 10, 30, None), "ros1")
    data = path.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    log = read_log(cut)
    assert 0 < len(log.scans) < 30 and all(
        same_scan(s, intel.scan(10 + k)) for k, s in enumerate(log.scans)
    )
    assert any("cut short" in n and "the rest is lost" in n for n in log.notes)
    res = CliRunner().invoke(app, ["eval", "sequence", str(cut), "--out", str(tmp_path / "o.json")])
    assert res.exit_code == 0 and "cut short" in res.output
    cut.write_bytes(data[:2000])  # nothing left to read: an error, not an empty log
    with pytest.raises(InputError):
        read_log(cut)


def test_the_debugger_switches_topics_and_shows_the_odometry(tmp_path, intel, laserazos):
    """A bag with two scanners opens on the topic asked for; the debugger's picker reads the other
    one (never both); the object scan at the bag's odometry is a layer, with its distance in the
    result."""
    from mbicp_viz.views import scene
    from mbicp_viz.views.debugger import report
    from mbicp_viz.views.debugger.sources import files_source
    from mbicp_viz.views.debugger.state import DebugState

    robot = intel_robot(intel, 30, 4, MOUNT)
    robot.topics.append(Topic("/rear/scan", "rear_laser", [laserazos.scan(k) for k in range(4)]))
    path = write(tmp_path / "two.bag", robot, "ros1")
    state = DebugState(
        files_source(str(path), None, guess="identity", options=ReadOptions(topic="/scan"))
    )
    assert state.rematch() is None and set(state.source.log.scan_topics) == {"/scan", "/rear/scan"}
    paths = {ly.path: ly for ly in report.layers(state, state.runs[0])}
    odometry = paths[f"{scene.SCANS}/odometry"]
    assert odometry.style is scene.ODOMETRY
    laser = relative(intel.scan(30).pose, intel.scan(31).pose)  # the odometry, seen by the laser
    assert np.allclose(odometry.xy, laser.apply(state.runs[0].start.obj_points), atol=1e-9)
    assert "from the odometry (/odom (nav_msgs/Odometry))" in report.result_markdown(state)

    assert state.set_topic("/rear/scan") is None
    log = state.source.log
    assert (
        log.topic == "/rear/scan" and log.frames.frame_id == "rear_laser" and state.pair == (0, 1)
    )
    assert same_scan(state.ref, laserazos.scan(0)) and same_scan(state.obj, laserazos.scan(1))
    # refused, kept
    assert state.set_topic("/nope") is not None and state.source.log.topic == "/rear/scan"


@pytest.mark.parametrize("plugin", ["SQLITE3", "MCAP"])
def test_a_ros2_bag_without_laser_scans_says_so_and_lists_its_topics(tmp_path, plugin):
    """No message is decoded to find that out: rosbags reads every topic when asked for none."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    string = ts.types["std_msgs/msg/String"]
    path = tmp_path / "chatter"
    with Writer(path, version=8, storage_plugin=getattr(StoragePlugin, plugin)) as w:
        conn = w.add_connection("/chatter", "std_msgs/msg/String", typestore=ts)
        for k in range(3):
            w.write(conn, k, ts.serialize_cdr(string(data=f"hi {k}"), "std_msgs/msg/String"))
    res = CliRunner().invoke(app, ["match", str(path), "--pair", "0", "1"])
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert (
        "no sensor_msgs/msg/LaserScan topic; the bag has: /chatter (std_msgs/msg/String, 3 "
        "messages)" in res.stderr
    )


@pytest.mark.parametrize("plugin", ["SQLITE3", "MCAP"])
def test_a_ros2_bag_whose_laser_scan_topic_holds_no_message_says_so(tmp_path, plugin):
    """A LaserScan topic declared but empty (a recording stopped before the laser spoke, or a
    damaged index that lists none of its messages): one line, not a traceback."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    string = ts.types["std_msgs/msg/String"]
    path = tmp_path / "silent"
    with Writer(path, version=8, storage_plugin=getattr(StoragePlugin, plugin)) as w:
        w.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=ts)
        conn = w.add_connection("/chatter", "std_msgs/msg/String", typestore=ts)
        w.write(conn, 1, ts.serialize_cdr(string(data="hi"), "std_msgs/msg/String"))
    res = CliRunner().invoke(app, ["match", str(path), "--pair", "0", "1"])
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert f"{path}: no message on its sensor_msgs/msg/LaserScan topics: /scan" in res.stderr


def test_a_bag_whose_odometry_starts_after_its_first_scan_is_matched_whole(tmp_path, intel):
    """The first scan precedes the first odometry message (a driver that starts late): that pair
    is matched from the identity and said so, the others from the odometry."""
    robot = intel_robot(intel, 10, 6, MOUNT, odometry_from=1)
    path = write(tmp_path / "late.bag", robot, "ros1")
    out = tmp_path / "rows.json"
    args = ["eval", "sequence", str(path), "--guess", "odometry", "--out", str(out)]
    res = CliRunner().invoke(app, [*args, "--workers", "1"])
    assert res.exit_code == 0, res.output
    rows = json_lines(out)
    assert len(rows) == 5 and rows[0]["guess"] == "identity: no odometry at one of the scans"
    assert {r["guess"] for r in rows[1:]} == {"odometry"}
    assert "1 pair(s) with no odometry at one of their scans: matched from the identity" in (
        res.stderr
    )


def test_odometry_on_tf_is_read_where_tf_does_not_link_the_laser(tmp_path, intel):
    """A TurtleBot-like bag: odom -> base_link on /tf, the laser's mount published nowhere the
    reader looks. Its odometry is read; --mount puts it onto the laser; without, a note says the
    base's odometry stands for the laser's."""
    robot = intel_robot(intel, 10, 6, MOUNT, odometry_on="/tf", mount_on="/elsewhere")
    path = write(tmp_path / "tb.bag", robot, "ros1")
    log = read_log(path)
    assert all(s.odometry is not None for s in log.scans)
    assert any("no mount of the laser 'laser' is known" in n for n in log.notes)
    mounted = read_log(path, ReadOptions(mount=MOUNT))
    assert mounted.frames.mount_source == "--mount"
    for k in range(5):  # the laser's motion by the odometry: the log's own scan poses
        laser = relative(intel.scan(10 + k).pose, intel.scan(11 + k).pose)
        by_odometry = relative(mounted.scans[k].odometry, mounted.scans[k + 1].odometry)
        assert pose_error(by_odometry, laser)[0] < 1e-6


def test_two_static_mounts_that_disagree_are_said(tmp_path, intel):
    robot = intel_robot(intel, 10, 3, MOUNT, mount_again=Pose2(0.1, 0.0, 0.0))
    log = read_log(write(tmp_path / "two.bag", robot, "ros1"))
    assert log.frames.mount == Pose2(0.1, 0.0, 0.0)  # the last published
    assert any(
        "/tf_static gives base_link -> laser several different values" in n for n in log.notes
    )
    assert not any(
        "several" in n
        for n in read_log(
            write(tmp_path / "one.bag", intel_robot(intel, 10, 3, MOUNT), "ros1")
        ).notes
    )


@pytest.mark.parametrize(
    "kind, damage, said",
    [
        ("mcap", (b"float32[] ranges", b"float32[] rangez"), "field 'ranges' should hold floats"),
        ("mcap", (b"float32 angle_min", b"int32 angle_min  "), "field 'angle_min' should hold a"),
        ("mcap", (b"string frame_id", b"string frame_ix"), "field 'header.frame_id' should hold"),
    ],
)
def test_a_bag_whose_own_definition_of_a_type_is_damaged_says_so(
    tmp_path, intel, kind, damage, said
):
    """An MCAP file carries its types' definitions (schemas) and is decoded by them: a damaged
    one is one line naming the field, never a traceback or a number read as another type (a bare
    .mcap has no metadata hash that would catch it first)."""
    bag = write(
        tmp_path / ("r.bag" if kind == "ros1" else "r"), intel_robot(intel, 0, 3, None), kind
    )
    src = bag if kind == "ros1" else next(bag.glob("*.mcap"))
    data = src.read_bytes()
    assert damage[0] in data
    damaged = tmp_path / f"damaged{src.suffix}"
    damaged.write_bytes(data.replace(*damage))
    res = CliRunner().invoke(app, ["match", str(damaged), "--pair", "0", "1"])
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert said in res.stderr and "the bag's definition of its type is damaged" in res.stderr
    assert str(damaged) in res.stderr
