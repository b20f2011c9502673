"""Recordings as long as robots make them: bags read through their index (each scan when it is
asked for), long bags written from real scans played to and fro, runs streamed with bounded
memory."""

import math
import os
import re
import shutil
import statistics
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.core import ImprovedParams, Pose2, pose_error
from mbicp_viz.errors import InputError
from mbicp_viz.evaluation import pool
from mbicp_viz.evaluation.bench import run_measured
from mbicp_viz.readers import read_log
from mbicp_viz.readers.bag_index import OdometryWindow, bracket
from mbicp_viz.readers.ros2_index import topic_stamps
from mbicp_viz.readers.rosbag import DEFAULT_TYPESTORE, _to_log, _walk_ros1, open_bag
from mbicp_viz.readers.tf import interpolate
from mbicp_viz.writers.replay import Replay, replayed, resampled

from .bags import intel_robot, write
from .conftest import DATA, HOKUYO_BAG, INTEL, json_lines
from .test_bags import same_scan

MOUNT = Pose2(0.2, 0.05, math.radians(10.0))


def walked(path: Path):
    """The bag read whole, message by message, by the reader that does not use its index."""
    notes = []
    return _to_log(str(path), _walk_ros1(path, notes, "test"), None, notes, None)


@pytest.mark.parametrize("odometry_on", ["/odom", "/tf"])
def test_scans_read_through_the_index_equal_the_bag_read_whole(tmp_path, intel, odometry_on):
    path = write(
        tmp_path / "r.bag", intel_robot(intel, 0, 40, MOUNT, odometry_on=odometry_on), "ros1"
    )
    lazy, whole = read_log(path), walked(path)
    assert lazy.store is not None and whole.store is None
    assert lazy.frames == whole.frames and lazy.odometry_source == whole.odometry_source
    assert lazy.records == whole.records == 40
    for k in [39, 0, 17, 18, 3]:  # any record, in any order
        a, b = lazy.scan(k), whole.scan(k)
        assert same_scan(a, b) and a.stamp == b.stamp
        assert a.odometry is not None and np.allclose(a.odometry.as_array(), b.odometry.as_array())
    streamed = list(lazy.store.stream())  # a whole run reads the bag once, front to back
    assert [r for r, _ in streamed] == list(range(40))
    for r, s in streamed:
        b = whole.scan(r)
        assert same_scan(s, b) and np.allclose(s.odometry.as_array(), b.odometry.as_array())
    # Python floats: numpy scalars would slow every step of a run that reads them
    for s in (lazy.scan(5), streamed[5][1]):
        assert {type(v) for v in (s.odometry.x, s.odometry.y, s.odometry.theta)} == {float}


# stamps that repeat (two samples of one instant), in steps within ``interpolate``'s largest gap
stamps = st.sampled_from([0.0, 0.25, 0.5, 0.75]) | st.floats(-0.5, 1.0)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.tuples(stamps, st.floats(-5, 5), st.floats(-5, 5), st.floats(-3, 3)), max_size=8),
    stamps,
)
def test_the_odometry_a_scan_reads_is_interpolated_as_from_its_whole_window_sorted(samples, t):
    """A scan's odometry interpolated from its window's two samples around it (``bracket``)
    equals the window sorted by stamp (stable: equal stamps in arrival order) and interpolated
    whole, at any stamp: repeated, unordered, before, on or after the samples."""
    a = np.array(samples, dtype=float).reshape(-1, 4)
    order = np.argsort(a[:, 0], kind="stable")
    whole = interpolate(a[order, 0], a[order, 1:], t)
    assert interpolate(*bracket(samples, t), t) == whole


@settings(max_examples=500, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(0, 0.05),  # each message's record stamp after the last one's
            # its samples' stamps, each after the one before but now and then (or equal)
            st.lists(st.tuples(st.sampled_from([0.0, 0.1, 0.1, 0.2, -0.3]), st.floats(-3, 3))),
        ),
        max_size=20,
    ),
    st.floats(0, 1),
    st.floats(0, 1),
    st.integers(0, 40) | st.floats(-0.5, 3.0),
    st.integers(0, 40),
    st.sampled_from([0, 3, 4096]),
)
def test_a_streams_odometry_window_finds_the_samples_a_scan_reads(
    messages, a, b, at, drops, compact_after
):
    """``OdometryWindow.around`` answers as ``bracket`` over the samples of the messages
    recorded within the window, whatever is left after dropping the earlier ones (still listed,
    or dropped for good), whether the samples' own stamps increase (bisection) or not (a pass)."""
    window, records, record, stamp = OdometryWindow(compact_after), [], 0.0, 0.0
    for step, steps in messages:
        record += step
        samples = []
        for d, theta in steps:
            stamp = round(stamp + d, 6)
            samples.append((stamp, 0.0, 0.0, theta))
        window.add(record, samples)
        records += [(record, x) for x in samples]
    # at a sample's stamp (repeated stamps hold several) or anywhere
    t = records[at % len(records)][1][0] if isinstance(at, int) and records else float(at)
    lo, hi = min(a, b), max(a, b)
    cut = records[min(drops, len(records) - 1)][0] if records else 0.0
    window.drop_before(min(cut, lo))
    near = [x for r, x in records if lo <= r < hi]
    assert interpolate(*window.around(lo, hi, t), t) == interpolate(*bracket(near, t), t)


def recompressed(src: Path, dst: Path, compression: str) -> Path:
    """``src`` written again by rosbags' own writer, its chunks compressed (bz2 or lz4)."""
    from rosbags.rosbag1 import Reader, Writer

    w = Writer(dst)
    w.chunk_threshold = 16 * 1024
    w.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    with Reader(src) as r, w:
        conns = {
            c.id: w.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest)
            for c in r.connections
        }
        for c, t, raw in r.messages():
            w.write(conns[c.id], t, raw)
    return dst


@pytest.mark.parametrize("compression", ["bz2", "lz4"])
def test_a_bag_with_compressed_chunks_is_read_through_its_index(tmp_path, intel, compression):
    plain = write(tmp_path / "r.bag", intel_robot(intel, 0, 30, MOUNT), "ros1")
    path = recompressed(plain, tmp_path / f"{compression}.bag", compression)
    assert f"compression={compression}".encode() in path.read_bytes()
    packed, whole = read_log(path), walked(plain)
    assert packed.store is not None and packed.records == 30 and not packed.notes
    for k in [29, 0, 14]:
        a, b = packed.scan(k), whole.scan(k)
        assert same_scan(a, b) and a.stamp == b.stamp
        assert np.allclose(a.odometry.as_array(), b.odometry.as_array())


def test_the_hokuyo_bag_is_read_through_its_odd_index_as_walking_it_reads_it():
    """demo.bag's index-data records announce 20 bytes per entry where the format has 12 (rosbags
    refuses it): their entry count is right, so the index is read, and gives what walking the
    whole bag gives."""
    lazy, whole = read_log(HOKUYO_BAG), walked(HOKUYO_BAG)
    assert lazy.store is not None and lazy.records == whole.records == 360 and not lazy.notes
    for k in [359, 0, 180, 181]:
        a, b = lazy.scan(k), whole.scan(k)
        assert same_scan(a, b) and a.stamp == b.stamp


@pytest.mark.parametrize("kind", ["humble", "mcap"])
def test_ros2_bags_read_through_their_index_like_ros1(tmp_path, intel, kind):
    robot = intel_robot(intel, 0, 12, MOUNT)
    ros1 = read_log(write(tmp_path / "r.bag", robot, "ros1"))
    ros2 = read_log(write(tmp_path / "r2", robot, kind))
    assert ros2.store is not None and ros2.records == 12
    for k in (11, 0, 5):
        assert same_scan(ros2.scan(k), ros1.scan(k))
        assert np.allclose(ros2.scan(k).odometry.as_array(), ros1.scan(k).odometry.as_array())


def zstd_compressed(src: Path, dst: Path, kind: str, mode: str = "file") -> Path:
    """The ROS 2 bag ``src`` written again by rosbags' own writer (as MCAP or sqlite3), each
    storage file or each message compressed with zstd (``ros2 bag record --compression-mode
    file`` or ``message``)."""
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
    with Reader(src) as r:
        w = Writer(dst, version=8, storage_plugin=plugin)
        w.set_compression(CompressionMode[mode.upper()], CompressionFormat.ZSTD)
        with w:
            ts = get_typestore(Stores.ROS2_HUMBLE)  # a Humble bag stores no definitions
            conns = {
                c.id: w.add_connection(c.topic, c.msgtype, typestore=ts) for c in r.connections
            }
            for c, t, raw in r.messages():
                w.write(conns[c.id], t, raw)
    return dst


@pytest.mark.parametrize("kind", ["humble", "mcap"])
def test_a_ros2_bag_compressed_file_by_file_is_decompressed_once_into_the_cache(
    tmp_path, intel, kind, monkeypatch
):
    """Its zstd files are decompressed the first time into the cache, never beside the bag, and
    read from there the next times (rosbags would decompress them at each opening); its scans
    equal the uncompressed bag's, and it says so."""
    monkeypatch.setenv("MBICP_VIZ_CACHE", str(tmp_path / "cache"))
    plain = write(tmp_path / "r2", intel_robot(intel, 0, 12, MOUNT), kind)
    path = zstd_compressed(plain, tmp_path / "z", kind)
    beside = sorted(p.name for p in path.iterdir())
    assert all(n == "metadata.yaml" or n.endswith(".zstd") for n in beside)
    first, again, whole = read_log(path), read_log(path), read_log(plain)
    assert any("decompressed once into" in n for n in first.notes), first.notes
    assert any("read from their decompressed copy" in n for n in again.notes), again.notes
    assert sorted(p.name for p in path.iterdir()) == beside
    (entry,) = (tmp_path / "cache" / "logs").iterdir()
    made = {f.name: f.stat().st_mtime_ns for f in entry.iterdir()}
    for log in (first, again):
        assert log.store is not None and log.records == 12
        for k in (11, 0, 5):
            assert same_scan(log.scan(k), whole.scan(k))
            assert np.allclose(log.scan(k).odometry.as_array(), whole.scan(k).odometry.as_array())
    assert {f.name: f.stat().st_mtime_ns for f in entry.iterdir() if f.name != "meta.json"} == {
        n: t for n, t in made.items() if n != "meta.json"
    }


def test_a_ros2_bag_that_decompresses_past_the_cache_is_left_to_rosbags(
    tmp_path, intel, monkeypatch
):
    """A few compressed bytes may decompress to many: past what the whole cache may hold, the
    copy is abandoned (nothing left in the cache) and rosbags decompresses at each opening."""
    from mbicp_viz.readers import ros2_storage

    monkeypatch.setenv("MBICP_VIZ_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(ros2_storage, "CACHE_BYTES", 10_000)
    plain = write(tmp_path / "r2", intel_robot(intel, 0, 12, MOUNT), "mcap")
    log = read_log(zstd_compressed(plain, tmp_path / "z", "mcap"))
    assert any("decompress to more than the cache holds" in n for n in log.notes), log.notes
    assert log.records == 12 and same_scan(log.scan(11), read_log(plain).scan(11))
    assert not any((tmp_path / "cache" / "logs").iterdir())


@pytest.mark.parametrize("kind", ["humble", "mcap"])
def test_a_storage_file_of_a_bag_of_compressed_messages_is_read_through_its_folder(
    tmp_path, intel, kind
):
    """Only the folder's metadata says that each message is compressed: the file opened alone
    (read as undecodable messages before) is read through its folder, and says so."""
    plain = write(tmp_path / "r2", intel_robot(intel, 0, 12, MOUNT), kind)
    path = zstd_compressed(plain, tmp_path / "z", kind, "message")
    (storage,) = (f for f in path.iterdir() if f.suffix in (".db3", ".mcap"))
    log, whole = read_log(storage), read_log(plain)
    assert any("read through its folder" in n for n in log.notes), log.notes
    assert log.records == 12 and all(same_scan(log.scan(k), whole.scan(k)) for k in (0, 11))


@pytest.fixture(scope="module")
def chunked_mcap(tmp_path_factory) -> Path:
    """An MCAP bag of 1,200 real scans of 1081 beams, in several chunks (rosbags closes one past
    1 MB)."""
    out = tmp_path_factory.mktemp("mcap") / "m"
    args = ["bench", "bag", str(out), "--from", str(INTEL), "--minutes", "0.5", "--kind", "mcap"]
    result = CliRunner().invoke(app, args + ["--rate-hz", "40", "--beams", "1081"])
    assert result.exit_code == 0, result.output
    return out


@settings(max_examples=8, deadline=None)
@given(fraction=st.floats(0.5, 0.999))
def test_an_mcap_file_cut_short_is_read_to_its_cut(tmp_path_factory, chunked_mcap, fraction):
    """A recording cut short (no summary, no footer: rosbags refuses it) is read up to its last
    whole chunk from a closed copy in the cache, through the index the copy was given: its scans
    are the whole bag's first ones, the command says how many bytes were lost, the next opening
    reads the copy, and the file itself is left as it was."""
    tmp = tmp_path_factory.mktemp("cut")
    (whole_file,) = chunked_mcap.glob("*.mcap")
    data = whole_file.read_bytes()
    cut = tmp / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * fraction)])
    os.environ["MBICP_VIZ_CACHE"], before = str(tmp / "cache"), os.environ["MBICP_VIZ_CACHE"]
    try:
        first, again, whole = read_log(cut), read_log(cut), read_log(chunked_mcap)
        reader = open_bag(cut, DEFAULT_TYPESTORE)  # the copy, through the index it was given
        try:
            indexed = topic_stamps(reader, "/scan", str(cut))
        finally:
            reader.close()
    finally:
        os.environ["MBICP_VIZ_CACHE"] = before
    (said,) = [n for n in first.notes if "cut short (no MCAP footer" in n]
    lost = int(re.search(r"the (\d+) bytes after them lost", said)[1])
    assert 0 <= lost < 1_100_000  # at most the chunk the cut went through (rosbags: 1 MB each)
    assert any("read from its closed copy" in n for n in again.notes), again.notes
    assert cut.read_bytes() == data[: int(len(data) * fraction)]
    assert 0 < first.records <= whole.records  # all of them when the cut is in the summary
    assert indexed is not None and np.array_equal(indexed, first.store.stamps_ns)
    for k in (0, first.records - 1):
        a, b = first.scan(k), whole.scan(k)
        assert same_scan(a, b) and a.stamp == b.stamp and same_scan(again.scan(k), b)


@pytest.mark.parametrize("size", [20, 100_000])
def test_an_mcap_file_cut_before_its_first_chunk_ended_is_said(
    tmp_path, chunked_mcap, monkeypatch, size
):
    """Cut inside its header, or inside its first chunk: no message to read, said in one line
    naming the file, and no copy made."""
    monkeypatch.setenv("MBICP_VIZ_CACHE", str(tmp_path / "cache"))
    (whole_file,) = chunked_mcap.glob("*.mcap")
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole_file.read_bytes()[:size])
    with pytest.raises(InputError, match="cut short .* no message to read") as e:
        read_log(cut)
    assert e.value.path == str(cut) and not (tmp_path / "cache").exists()


def test_an_mcap_file_whose_first_chunk_is_too_short_for_its_head_is_said(
    tmp_path, chunked_mcap, monkeypatch
):
    """A chunk record whole by its length but too short to hold a chunk's head (damage where the
    cut left it) ends the data like a chunk that does not decompress: one line, no traceback."""
    import struct

    monkeypatch.setenv("MBICP_VIZ_CACHE", str(tmp_path / "cache"))
    (whole_file,) = chunked_mcap.glob("*.mcap")
    data = whole_file.read_bytes()
    (header_length,) = struct.unpack_from("<Q", data, 9)  # after the magic and the opcode
    head = data[: 8 + 9 + header_length]
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(head + struct.pack("<BQ", 0x06, 5) + bytes(5) + b"\x01" * 40)
    with pytest.raises(InputError, match="before its first chunk ended") as e:
        read_log(damaged)
    assert e.value.path == str(damaged)


@pytest.mark.parametrize("kind", ["humble", "mcap"])
def test_a_recording_stopped_before_its_metadata_was_written_is_read(
    tmp_path, intel, kind, chunked_mcap, monkeypatch
):
    """A recorder killed leaves a folder of one storage file and no metadata.yaml (rosbags refuses
    the folder): the file is read alone, and said; an MCAP one is also cut short (no footer) and
    read to its cut."""
    monkeypatch.setenv("MBICP_VIZ_CACHE", str(tmp_path / "cache"))
    plain = write(tmp_path / "r2", intel_robot(intel, 0, 12, MOUNT), kind)
    killed = tmp_path / "killed"
    killed.mkdir()
    (storage,) = (f for f in plain.iterdir() if f.suffix in (".db3", ".mcap"))
    shutil.copy(storage, killed / storage.name)
    log, whole = read_log(killed), read_log(plain)
    assert any("no metadata.yaml" in n and "read alone" in n for n in log.notes), log.notes
    assert log.records == 12 and all(same_scan(log.scan(k), whole.scan(k)) for k in (0, 11))
    (mcap,) = chunked_mcap.glob("*.mcap")
    cut = tmp_path / "killed-mcap"
    cut.mkdir()
    (cut / mcap.name).write_bytes(mcap.read_bytes()[: mcap.stat().st_size * 3 // 4])
    log, whole = read_log(cut), read_log(chunked_mcap)
    assert any("read alone" in n for n in log.notes) and any("cut short" in n for n in log.notes)
    assert same_scan(log.scan(log.records - 1), whole.scan(log.records - 1))


@pytest.mark.parametrize("topic", ["/tf_static", "/scan"])
def test_a_sqlite3_bag_whose_record_stamp_is_not_a_number_is_said(tmp_path, intel, topic):
    """A damaged row read at the opening (a flipped byte made a stamp NULL in the fuzz; here a
    text) is one line naming the bag, not a TypeError from arithmetic on it."""
    import sqlite3

    path = write(tmp_path / "r2", intel_robot(intel, 0, 12, MOUNT), "humble")
    (db,) = path.glob("*.db3")
    with sqlite3.connect(db) as c:
        (row,) = c.execute(
            "SELECT max(messages.id) FROM messages JOIN topics ON topic_id = topics.id "
            "WHERE name = ?",
            (topic,),
        ).fetchone()
        c.execute("UPDATE messages SET timestamp = 'damaged' WHERE id = ?", (row,))
    with pytest.raises(InputError, match="has no record stamp") as e:
        read_log(path)
    assert e.value.path == str(path)


def test_a_truncated_zstd_file_of_a_ros2_bag_is_said_and_leaves_no_cache_entry(
    tmp_path, intel, monkeypatch
):
    monkeypatch.setenv("MBICP_VIZ_CACHE", str(tmp_path / "cache"))
    plain = write(tmp_path / "r2", intel_robot(intel, 0, 12, MOUNT), "mcap")
    path = zstd_compressed(plain, tmp_path / "z", "mcap")
    (z,) = path.glob("*.zstd")
    z.write_bytes(z.read_bytes()[: z.stat().st_size // 2])
    with pytest.raises(InputError, match="not a whole zstd stream") as e:
        read_log(path)
    assert e.value.path == str(z)
    assert not any((tmp_path / "cache" / "logs").iterdir())


@pytest.mark.parametrize("kind", ["humble", "mcap"])
def test_a_ros2_bags_scan_stamps_are_read_from_its_storage_index(tmp_path, intel, kind):
    """A ROS 2 bag's scan stamps come from its storage's own index (sqlite3's timestamp column,
    the message indexes after MCAP's chunks), equal to what one pass over its messages gives,
    and its odometry's are not among them."""
    path = write(tmp_path / "r2", intel_robot(intel, 0, 40, MOUNT), kind)
    reader = open_bag(path, DEFAULT_TYPESTORE)
    try:
        scans = [c for c in reader.connections if c.topic == "/scan"]
        stamps = topic_stamps(reader, "/scan", str(path))
        passed = np.fromiter((t for _, t, _ in reader.messages(scans)), dtype=np.int64)
        assert stamps is not None and len(stamps) == 40 and np.array_equal(stamps, passed)
    finally:
        reader.close()


def test_an_mcap_chunk_index_pointing_past_its_message_index_is_said(tmp_path, intel):
    """An MCAP bag whose chunk index points where no message index is (a damaged file) is refused
    in one line naming the bag and the byte, not read wrongly."""
    from rosbags.rosbag2.storage_mcap import McapReader

    path = write(tmp_path / "r2", intel_robot(intel, 0, 12, MOUNT), "mcap")
    (mcap,) = path.glob("*.mcap")
    storage = McapReader(mcap)
    storage.open()
    (scans,) = [c.id for c in storage.connections if c.topic == "/scan"]
    at = storage.chunks[0].message_index_offsets[scans]
    storage.close()
    data = bytearray(mcap.read_bytes())
    data[at] ^= 0xFF  # the message index record's opcode
    mcap.write_bytes(bytes(data))
    with pytest.raises(InputError) as e:
        read_log(path)
    assert str(path) in str(e.value) and f"byte {at}" in str(e.value)


@pytest.mark.parametrize("shift_s", [0.25, 1e6])
def test_an_mcap_message_index_at_odds_with_its_messages_is_said(tmp_path, intel, shift_s):
    """A scan's time in the message index changed (within its chunk's time, or far outside it):
    the stamps come from that index, so reading that scan, or the run that reads every message,
    is refused in one line naming the bag, exit 2; never a scan that is not there."""
    from rosbags.rosbag2.storage_mcap import McapReader

    path = write(tmp_path / "r2", intel_robot(intel, 0, 12, MOUNT), "mcap")
    (mcap,) = path.glob("*.mcap")
    storage = McapReader(mcap)
    storage.open()
    (scans,) = [c.id for c in storage.connections if c.topic == "/scan"]
    at = storage.chunks[0].message_index_offsets[scans] + 15  # its first (log time, offset)
    storage.close()
    data = bytearray(mcap.read_bytes())
    first = int.from_bytes(data[at : at + 8], "little")
    data[at : at + 8] = (first + int(shift_s * 1e9)).to_bytes(8, "little")
    mcap.write_bytes(bytes(data))
    out = str(tmp_path / "out.json")
    for args in (
        ["match", str(path), "--pair", "0", "1"],
        ["eval", "sequence", str(path), "--out", out],
    ):
        res = CliRunner().invoke(app, args)
        assert res.exit_code == 2 and "Traceback" not in res.output, res.output
        assert f"{path}: " in res.stderr and "index" in res.stderr, res.stderr


def test_a_long_bag_opens_without_reading_its_scans(tmp_path, intel):
    """The index is read, not the messages: a scan near the end is read alone, and the log does
    not look at every record until a command needs them."""
    path = tmp_path / "long.bag"
    code = CliRunner().invoke(
        app,
        ["bench", "bag", str(path), "--from", str(INTEL), "--minutes", "3", "--rate-hz", "40"],
    )
    assert code.exit_code == 0, code.output
    assert "7201 scans of 180 beams over 180 s (ros1" in code.output
    log = read_log(path)
    assert log.records == 7201 and log.known_unusable == {}
    survey = log.scans.survey
    assert log.scan(7000).stamp is not None and survey._usable is None  # read alone
    assert log.consecutive_pairs(3) == [(0, 1), (1, 2), (2, 3)] and survey._usable is None
    # a bag stores no scan poses: said without reading a scan (the run view asks for them all)
    cached = set(log.store._cache)
    assert np.isnan(log.poses_of(list(range(0, 7201, 7)))).all()
    assert set(log.store._cache) == cached and survey._usable is None
    # a map's scan, read without its odometry, is the scan; it is not kept
    bare = log.scan(5000, odometry=False)
    assert 5000 not in log.store._cache
    assert np.array_equal(bare.points(), log.scan(5000).points()) and 5000 in log.store._cache


def test_bench_bag_plays_real_scans_to_and_fro_with_real_intervals(tmp_path, intel):
    out = tmp_path / "m"
    args = ["bench", "bag", str(out), "--from", str(INTEL), "--minutes", "1", "--kind", "mcap"]
    args += ["--rate-hz", "10"]
    result = CliRunner().invoke(app, args + ["--beams", "361"])
    assert result.exit_code == 0, result.output
    log = read_log(out)
    n = len(intel.scans)
    play = Replay(n, log.records)
    dts = np.diff([s.stamp for s in intel.scans])
    for k in (0, 1, n - 1, n, 2 * n - 2, 2 * n + 3):  # forwards, the turn, backwards, forwards
        src = intel.scans[play[k]]
        assert same_scan(log.scan(k), resampled(src, 361))
        # the base's odometry played along, seen on the laser through the mount again
        assert max(pose_error(log.scan(k).odometry, src.odometry)) < 1e-6
    # the intervals are the real ones, scaled to 10 Hz on average; the first step back is the last
    first = log.scan(1).stamp - log.scan(0).stamp
    back = log.scan(n).stamp - log.scan(n - 1).stamp
    assert back / first == pytest.approx(dts[-1] / dts[0], rel=1e-6)
    assert (log.scan(600).stamp - log.scan(0).stamp) / 600 == pytest.approx(0.1, rel=0.05)
    assert CliRunner().invoke(app, args).exit_code == 2  # never over an existing output


@given(n=st.integers(1, 50), k=st.integers(0, 10_000))
def test_a_replay_moves_one_scan_at_a_time_and_stays_in_the_recording(n, k):
    play = Replay(n, 10_001)
    assert 0 <= play[k] < n
    if n > 1 and k < 10_000:
        assert abs(play[k + 1] - play[k]) == 1


def test_resampled_scans_read_the_nearest_real_beam(intel):
    s = intel.scans[0]
    r = resampled(s, 1081)
    assert len(r.ranges) == 1081 and r.bearings[0] == s.bearings[0]
    assert r.bearings[-1] == pytest.approx(s.bearings[-1])
    nearest = np.abs(s.bearings[None, :] - r.bearings[:, None]).argmin(axis=1)
    assert np.array_equal(r.ranges, s.ranges[nearest]) and np.array_equal(r.valid, s.valid[nearest])


def test_replaying_needs_stamps(intel):
    from dataclasses import replace

    from mbicp_viz.readers import ScanLog

    frozen = ScanLog("x", [replace(s, stamp=1.0) for s in intel.scans[:3]])
    with pytest.raises(ValueError, match="increasing stamps"):
        replayed(frozen, 10.0)


def peak_mb(args: list[str]) -> float:
    return run_measured(args)[1]


def test_memory_does_not_grow_with_the_bag(tmp_path):
    """A bag 8 times longer costs the same memory to open and match a late pair in, and a run over
    its first pairs streams them (the same pairs, the same peak)."""
    exe = [sys.executable, "-m", "mbicp_viz"]
    source = str(DATA / "hokuyo-demo.bag")
    peaks = {}
    for minutes in (1, 8):
        path = tmp_path / f"{minutes}.bag"
        make = exe + ["bench", "bag", str(path), "--from", source, "--minutes", str(minutes)]
        assert subprocess.run(make, capture_output=True).returncode == 0
        late = str(int(minutes * 600) - 2)
        peaks[minutes] = (
            peak_mb(exe + ["match", str(path), "--pair", late, str(int(late) + 1), "--json"]),
            peak_mb(
                exe
                + ["eval", "sequence", str(path), "--limit", "300", "--workers", "1"]
                + ["--out", str(tmp_path / f"{minutes}.json")]
            ),
        )
    assert (tmp_path / "8.bag").stat().st_size > 7 * (tmp_path / "1.bag").stat().st_size
    for short, long in zip(peaks[1], peaks[8]):
        assert long < short + 25, peaks  # MB
    rows = [json_lines(tmp_path / f"{m}.json") for m in (1, 8)]
    assert [(r["ref"], r["x"], r["theta"]) for r in rows[0]] == [
        (r["ref"], r["x"], r["theta"]) for r in rows[1]
    ]


def test_a_process_is_timed_to_the_moment_it_printed_or_to_its_end():
    """A server's first result is timed from the launch to the moment it printed, not to its stop:
    the work after the stamp is in the wall time to the end, not in the time to the stamp."""
    after_s = 0.4
    script = (
        "import time; t = time.monotonic(); print(t, flush=True)\n"
        f"while time.monotonic() < t + {after_s}: pass\n"
    )
    args = [sys.executable, "-c", script]
    t0 = time.monotonic()
    to_stamp, _ = run_measured(args, until_printed=True)
    around = time.monotonic() - t0  # the same process, launch to end and a little more
    assert 0.0 < to_stamp <= around - after_s
    to_end, peak = run_measured(args)
    assert to_end >= after_s and peak > 1.0
    with pytest.raises(RuntimeError, match="failed"):
        run_measured([sys.executable, "-c", "raise SystemExit(3)"], until_printed=True)


def test_bench_open_times_a_recordings_match_and_the_debuggers_first_result():
    out = CliRunner().invoke(
        app, ["bench", "open", str(HOKUYO_BAG), "--pair", "3", "4", "--repeat", "1"]
    )
    assert out.exit_code == 0, out.output
    times = dict(
        re.findall(r"^(match --pair 3 4|debugger first result) +([\d.]+) s", out.output, re.M)
    )
    assert set(times) == {"match --pair 3 4", "debugger first result"}, out.output
    assert all(0.1 < float(t) < 60.0 for t in times.values())


def test_a_run_makes_its_jobs_as_the_workers_need_them():
    made = []

    def jobs():
        for k in range(400):
            made.append(k)
            yield k

    seen = []

    def take(r):
        seen.append((r, len(made)))

    out = pool.ordered_map(abs, jobs(), 2, take, total=400)
    assert out == list(range(400))
    # when the first result came back, only the chunks sent ahead had been made
    size = pool.chunk_size(400, 2)
    assert seen[0][1] <= pool.IN_FLIGHT_PER_WORKER * 2 * size + size < 400


def test_bench_throughput_times_the_run_eval_sequence_makes(intel):
    """The replayed run is the recording played at the asked rate and beam count, and its
    real-time factor is the recording's duration over the median wall time of its runs."""
    from mbicp_viz.evaluation.throughput import replay_log, throughput
    from mbicp_viz.readers.params_toml import make_params

    run = replay_log(intel, 6, 90, 20.0)
    assert len(run.scans) == 7 and all(len(s.ranges) == 90 for s in run.scans)
    assert np.mean(np.diff([s.stamp for s in run.scans])) == pytest.approx(0.05, rel=0.5)
    t = throughput(intel, make_params("improved", None), 90, 6, 20.0, [1], repeat=3)
    assert t.pairs == 6 and t.seconds == pytest.approx(run.scans[-1].stamp - run.scans[0].stamp)
    assert len(t.walls_s[1]) == 3 and t.wall_s[1] == sorted(t.walls_s[1])[1]
    line = t.line()
    assert "90 beams" in line and "(median of 3 runs)" in line
    assert f"{t.seconds / t.wall_s[1]:6.1f}x real time on 1 core" in line


def test_bench_throughput_also_times_the_pairs_split_between_separate_processes(intel):
    """How far the cores scale with nothing shared, beside the run's pool: each pair matched in
    exactly one of the separate processes."""
    from mbicp_viz.evaluation.throughput import replay_log, split, throughput
    from mbicp_viz.readers.params_toml import make_params

    run = replay_log(intel, 9, 90, 20.0)
    shares = split(run, 2)
    pairs = [(a.stamp, b.stamp) for log in shares for a, b in zip(log.scans, log.scans[1:])]
    assert pairs == [(a.stamp, b.stamp) for a, b in zip(run.scans, run.scans[1:])]
    t = throughput(intel, make_params("improved", None), 90, 9, 20.0, [1, 2], repeat=2)
    assert len(t.apart_s) == 2 and min(t.apart_s) > 0.0
    alone = t.wall_s[1] / statistics.median(t.apart_s)
    assert f"scaling {t.wall_s[1] / t.wall_s[2]:.2f}x on 2" in t.line()
    assert f"(separate processes, nothing shared: {alone:.2f}x)" in t.line()


def test_bench_throughput_times_eval_sequence_itself_on_a_bag_of_the_same_run(intel):
    """The second figure is `eval sequence`'s own pace on a bag written from the replayed run:
    the recording's duration is the run's, and a failing run says why instead of a number."""
    from mbicp_viz.evaluation.throughput import from_bag, replay_log

    run = replay_log(intel, 6, 90, 20.0)
    t = from_bag(intel, ["--algo", "improved"], 90, 6, 20.0, [1])
    assert t.pairs == 6 and t.seconds == pytest.approx(run.scans[-1].stamp - run.scans[0].stamp)
    assert len(t.walls_s[1]) == 1 and t.walls_s[1][0] > 0.0
    assert "eval sequence on a ROS 1 bag" in t.line()
    with pytest.raises(InputError, match="no-such-preset: no such file"):
        from_bag(intel, ["--params", "no-such-preset"], 90, 6, 20.0, [1])


def test_bench_throughput_prints_the_run_in_memory_and_eval_sequence_on_a_bag():
    out = CliRunner().invoke(
        app,
        ["bench", "throughput", "--from", str(INTEL), "--beams", "90", "--pairs", "4"]
        + ["--repeat", "1"],
    )
    assert out.exit_code == 0, out.output
    lines = [ln for ln in out.output.splitlines() if ln.lstrip().startswith("90 beams")]
    assert len(lines) == 2
    assert "matched in memory" in lines[0] and "eval sequence on a ROS 1 bag" in lines[1]
    assert all("x real time on 1 core" in ln for ln in lines)
    if (os.cpu_count() or 1) > 1:
        assert "separate processes, nothing shared" in lines[0]


def test_the_rows_of_a_pooled_run_share_one_parameters_object(intel):
    """Each worker sends its rows back pickled, parameters and all: taken back, the run's rows hold
    one parameters object, not a copy each (a day's run holds millions of rows)."""
    from mbicp_viz.core import ImprovedParams
    from mbicp_viz.evaluation.sequence import match_sequence

    rows = match_sequence(intel, ImprovedParams(L=2.0), limit=40, workers=2)
    assert len(rows) == 40 and len({id(r.params) for r in rows}) == 1
    assert rows[0].params == ImprovedParams(L=2.0)


def test_eval_sequence_says_its_pace(tmp_path):
    out = tmp_path / "r.json"
    result = CliRunner().invoke(
        app, ["eval", "sequence", str(DATA / "hokuyo-demo.bag"), "--limit", "5", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert "5 pairs matched in " in result.output and "x real time)" in result.output


def test_a_run_over_a_bag_read_through_its_index_steps_over_an_unusable_scan(tmp_path, intel):
    from mbicp_viz.core import make_scan

    from .bags import Robot, Topic

    scans = [intel.scan(k) for k in range(6)]
    scans[3] = make_scan(np.full(180, 81.9), scans[3].bearings, valid=np.ones(180, bool))
    path = write(
        tmp_path / "e.bag", Robot([Topic("/scan", "laser", scans)], [1, 2, 3, 4, 5, 6]), "ros1"
    )
    log = read_log(path)
    assert log.store is not None and log.known_unusable == {}  # not known before it is read
    assert [r for r, _ in log.scans_from(1)] == [1, 2, 4, 5]
    out = tmp_path / "r.json"
    res = CliRunner().invoke(
        app, ["eval", "sequence", str(path), "--out", str(out), "--workers", "2"]
    )
    assert res.exit_code == 0, res.output
    assert [(r["ref"], r["obj"]) for r in json_lines(out)] == [(0, 1), (1, 2), (2, 4), (4, 5)]
    assert "skipped 1 unusable scan(s) of 6 (first: scan 3" in res.output


def bag_with_unusable_scans(tmp_path, intel, unusable: tuple[int, ...], n: int = 14) -> Path:
    """A bag of ``n`` Intel scans with odometry, the scans of ``unusable`` all no-return codes."""
    from mbicp_viz.core import make_scan

    robot = intel_robot(intel, 0, n, MOUNT)
    scans = robot.topics[0].scans
    for k in unusable:
        scans[k] = make_scan(np.full(180, 81.9), scans[k].bearings, valid=np.ones(180, bool))
    return write(tmp_path / "u.bag", robot, "ros1")


def test_a_run_finds_its_pairs_as_it_reads_a_bag_once(tmp_path, intel, monkeypatch):
    """eval sequence on a bag read through its index does not read the bag a first time only to
    list its pairs: each scan is read once as the run goes (its first two once before, which say
    that the bag has a pair at all), and its rows are those of the pairs listed first."""
    from mbicp_viz.readers.bag_index import BagScans

    path = bag_with_unusable_scans(tmp_path, intel, (3, 8, 9))
    listed = read_log(path).consecutive_pairs()
    real, read = BagScans._scan, []
    monkeypatch.setattr(BagScans, "_scan", lambda self, k, *a: read.append(k) or real(self, k, *a))
    out = tmp_path / "r.json"
    res = CliRunner().invoke(app, ["eval", "sequence", str(path), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert [(r["ref"], r["obj"]) for r in json_lines(out)] == listed and len(listed) == 10
    # the first two, then the run's one pass (then the run's first and last scan, for its pace)
    assert read[:16] == [0, 1, *range(14)] and len(read) <= 18, read
    assert "skipped 3 unusable scan(s) of 14 (first: scan 3" in res.output


def test_a_run_over_a_bag_with_one_usable_scan_says_so_and_writes_nothing(tmp_path, intel):
    """Finding its pairs as it reads, a run still refuses a bag without a pair before it starts:
    one line, no rows file begun; a script calling the run gets the same error."""
    from mbicp_viz.evaluation.sequence import match_sequence

    path = bag_with_unusable_scans(tmp_path, intel, (0, 2, 3), n=4)
    with pytest.raises(InputError, match="needs at least two usable scans"):
        match_sequence(read_log(path), ImprovedParams())
    out = tmp_path / "r.json"
    res = CliRunner().invoke(app, ["eval", "sequence", str(path), "--out", str(out)])
    assert res.exit_code == 2 and "needs at least two usable scans" in res.stderr, res.output
    assert "Traceback" not in res.output and sorted(os.listdir(tmp_path)) == ["u.bag"]


def test_a_stopped_run_over_a_bag_resumes_from_its_rows_as_a_whole_run_matches(
    tmp_path, intel, monkeypatch
):
    """Stopped before the bag is read through, a run cannot know how many pairs it has: it
    says how many at most; the same command then goes on from its rows, checked against the
    bag's first pairs, to the rows of a run never stopped."""
    from .test_nothing_lost import interrupt_the_fourth_match

    path = bag_with_unusable_scans(tmp_path, intel, (2, 9))
    whole, out = tmp_path / "whole.json", tmp_path / "r.json"
    args = ["eval", "sequence", str(path), "--workers", "1", "--out"]
    assert CliRunner().invoke(app, [*args, str(whole)]).exit_code == 0
    with monkeypatch.context() as m:
        interrupt_the_fourth_match(m)
        res = CliRunner().invoke(app, [*args, str(out)])
    assert res.exit_code == 130 and not out.exists(), res.output
    assert re.search(r"interrupted after 4 of up to (\d+) pairs", res.stderr), res.stderr
    assert int(re.search(r"up to (\d+)", res.stderr)[1]) >= 11  # 14 scans, 2 unusable
    res = CliRunner().invoke(app, [*args, str(out)])
    assert res.exit_code == 0 and re.search(r"4 of up to \d+ pairs already matched", res.stderr)
    assert [(r["ref"], r["obj"], r["x"], r["theta"]) for r in json_lines(out)] == [
        (r["ref"], r["obj"], r["x"], r["theta"]) for r in json_lines(whole)
    ]
    assert len(json_lines(out)) == 11


def test_a_log_read_whole_is_cached_and_read_from_the_cache_alike(tmp_path, monkeypatch):
    """A CARMEN log is read whole once and cached outside its folder; the next opening maps the
    cache and reads each scan when asked for, every scan, pose, odometry and note as before."""
    import shutil

    from mbicp_viz.readers import log_cache

    monkeypatch.setenv("MBICP_VIZ_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(log_cache, "CACHED_RECORDS", 10)
    path = tmp_path / "ro" / "intel.log.gz"
    path.parent.mkdir()
    shutil.copy(INTEL, path)
    path.parent.chmod(0o555)  # a read-only input: nothing is written beside it
    try:
        whole = read_log(path)
        cached = read_log(path)
    finally:
        path.parent.chmod(0o755)
    assert whole.store is None and cached.store is not None
    assert os.listdir(path.parent) == ["intel.log.gz"]
    assert "cached in" in whole.notes[-1] and "read from its cache" in cached.notes[-1]
    assert cached.notes[:-1] == whole.notes[:-1]
    assert cached.records == whole.records and cached.frames == whole.frames
    assert cached.odometry == whole.odometry and cached.topic == whole.topic
    for k in [59, 0, 31]:
        a, b = cached.scan(k), whole.scan(k)
        assert np.array_equal(a.ranges, b.ranges) and np.array_equal(a.bearings, b.bearings)
        assert np.array_equal(a.valid, b.valid) and (a.pose, a.odometry, a.stamp) == (
            b.pose,
            b.odometry,
            b.stamp,
        )
        assert a.source == b.source
    assert cached.consecutive_pairs() == whole.consecutive_pairs()
    path.touch()  # the file changed: read whole again
    os.utime(path, ns=(1, 1))
    assert read_log(path).store is None


@settings(max_examples=30, deadline=None)
@given(n=st.integers(1, 70_000))
def test_a_long_trajectory_is_drawn_through_evenly_spaced_poses_ending_at_its_last(n):
    """... of which a line keeps those it needs: on a curve and a line of no width, all."""
    from mbicp_viz.views import scene

    poses = [Pose2(float(k), 1e-6 * k * k, 0.0) for k in range(n)]
    drawn = scene._drawn_track(poses, 0.0)[:, 0]
    assert len(drawn) <= scene.RUN_TRACK_VERTICES + 1 and drawn[0] == 0 and drawn[-1] == n - 1
    steps = np.diff(drawn)
    assert np.all(steps > 0) and (n <= scene.RUN_TRACK_VERTICES) == np.all(steps == 1)
    assert len(set(steps[:-1])) <= 1  # evenly spaced, but for the step to the last pose


@given(
    n=st.integers(0, 400),
    tol=st.floats(0.001, 1.0),
    seed=st.integers(0, 2**32 - 1),
    still=st.floats(0.0, 0.9),
)
def test_a_simplified_track_stays_within_its_tolerance_of_every_pose(n, tol, seed, still):
    """Douglas and Peucker: every pose left out lies within the tolerance of the segment drawn
    across it; the ends are kept, a straight run (or a robot standing still) is one segment per
    span of ``SIMPLIFIED_SPAN`` poses."""
    from mbicp_viz.views import scene

    rng = np.random.default_rng(seed)
    steps = rng.normal(size=(n, 2)) * rng.uniform(0.01, 1.0)
    steps[rng.random(n) < still] = 0.0  # standing still: the same pose again
    xy = np.cumsum(steps, axis=0)
    at = scene.simplified(xy, tol)
    assert list(at) == sorted(set(at)) and (n == 0 or (at[0] == 0 and at[-1] == n - 1))
    k = 0  # each pose's segment: between the kept vertices around it
    for i in range(n):
        while k + 1 < len(at) and at[k + 1] <= i:
            k += 1
        if at[k] == i or (k + 1 < len(at) and at[k + 1] == i):
            continue
        a, b = xy[at[k]], xy[at[k + 1]]
        d = b - a
        t = np.clip((xy[i] - a) @ d / max(d @ d, 1e-300), 0.0, 1.0)
        assert np.hypot(*(xy[i] - a - t * d)) <= tol * (1 + 1e-9)
    line = np.column_stack([np.linspace(0, 10, max(n, 2)), np.zeros(max(n, 2))])
    # a straight line: its ends, and the ends of the spans it is simplified in
    spans = list(range(0, max(n, 2), scene.SIMPLIFIED_SPAN))
    assert list(scene.simplified(line, tol)) == sorted({*spans, max(n, 2) - 1})


def test_every_scan_of_a_lazily_read_log_is_read_front_to_back(tmp_path, intel):
    path = write(tmp_path / "r.bag", intel_robot(intel, 0, 30, MOUNT), "ros1")
    log = read_log(path)
    loads = []
    real = log.store.load
    log.store.load = lambda k: loads.append(k) or real(k)
    stamps = [s.stamp for s in log.scans]  # one pass, no seek per scan
    assert len(stamps) == 30 and loads == [] and stamps == sorted(stamps)
    assert [s.stamp for s in walked(path).scans] == stamps


def test_a_pass_and_another_threads_scans_share_the_open_bag(tmp_path, intel):
    """The debugger's tabs are threads: one reading a run front to back while another opens
    pairs get the same scans as alone (one open reader: its steps are taken under a lock)."""
    import sys
    import threading

    robot, play = intel_robot(intel, 0, 60, MOUNT), Replay(60, 1200)
    played = [robot.topics[0].scans[play[k]] for k in range(1200)]
    robot = replace(
        robot,
        stamps=[100.0 + 0.05 * k for k in range(1200)],
        topics=[replace(robot.topics[0], scans=played)],
        odometry=[robot.odometry[play[k]] for k in range(1200)],
    )
    path = write(tmp_path / "r.bag", robot, "ros1")
    log, alone = read_log(path), walked(path)
    picked, errors = [], []

    def pairs():
        k = 0
        try:
            for _ in range(1000):
                k = (k * 7 + 13) % 1200
                log.store._cache.clear()
                picked.append((k, log.scan(k)))
        except Exception as e:
            errors.append(e)

    switch = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # threads take turns as often as they can
    try:
        other = threading.Thread(target=pairs)
        other.start()
        streamed = list(log.scans_from(0))
        other.join()
    finally:
        sys.setswitchinterval(switch)
    assert not errors and len(picked) == 1000
    for k, s in streamed + picked:
        assert same_scan(s, alone.scan(k)) and s.stamp == alone.scan(k).stamp


def test_a_damaged_cache_entry_is_read_whole_again(tmp_path, monkeypatch):
    from mbicp_viz.readers import log_cache

    monkeypatch.setenv("MBICP_VIZ_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(log_cache, "CACHED_RECORDS", 10)
    read_log(INTEL)
    folder = log_cache.entry(str(INTEL), "carmen", (None,))
    (folder / "ranges.npy").write_bytes(b"\\x93NUMPY cut short")
    again = read_log(INTEL)  # the entry is dropped, the file read whole and cached anew
    assert again.store is None and "cached in" in again.notes[-1]
    assert read_log(INTEL).store is not None


def test_the_cache_removes_its_least_recently_used_entries_beyond_its_size(tmp_path, monkeypatch):
    import shutil

    from mbicp_viz.readers import log_cache

    monkeypatch.setenv("MBICP_VIZ_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(log_cache, "CACHED_RECORDS", 10)
    logs = [tmp_path / f"{k}.log.gz" for k in range(3)]
    for k, path in enumerate(logs):
        shutil.copy(INTEL, path)
        os.utime(path, ns=(k + 1, k + 1))  # three files, three entries
    read_log(logs[0])
    size = sum(f.stat().st_size for f in log_cache.entry(str(logs[0]), "carmen", (None,)).iterdir())
    monkeypatch.setattr(log_cache, "CACHE_BYTES", int(2.5 * size))  # room for two entries
    read_log(logs[1])
    read_log(logs[0])  # used again: now the most recent
    read_log(logs[2])  # a third entry: the least recently used one goes
    kept = [log_cache.entry(str(p), "carmen", (None,)).is_dir() for p in logs]
    assert kept == [True, False, True]


def test_a_run_keeps_no_record_in_memory_as_it_goes(tmp_path, intel, monkeypatch):
    """eval sequence holds none of its records (an hour's 144,000 took 260 MB): each is written
    as it arrives and its columns kept; what it says at its end, it reads from them and from the
    rows file, as the records read back from the file say it."""
    import gc

    from mbicp_viz.cli import evaluate
    from mbicp_viz.evaluation.failures import failure_summary
    from mbicp_viz.evaluation.health import suspect_summary
    from mbicp_viz.evaluation.sequence import odometry_summary
    from mbicp_viz.readers.pair_match import PairMatch
    from mbicp_viz.readers.rows import PartialRows, read_rows

    n = len(intel.scans) - 1
    held, pace, add = {}, evaluate._pace, PartialRows.add

    def records() -> int:
        gc.collect()  # by type(): isinstance asks a weak proxy, an error once its object is gone
        return sum(type(o) is PairMatch for o in gc.get_objects())

    def adding(self, row):  # the last row as it arrives, and once the run is over
        if self.count == n - 1:
            held["last row"] = records()
        return add(self, row)

    def counted(lg, rows, resumed, seconds):
        held["run over"] = records()
        return pace(lg, rows, resumed, seconds)

    monkeypatch.setattr(PartialRows, "add", adding)
    monkeypatch.setattr(evaluate, "_pace", counted)
    bag = write(tmp_path / "i.bag", intel_robot(intel, 0, len(intel.scans), MOUNT), "ros1")
    out = tmp_path / "r.jsonl"
    # one process: a pool's finished chunks wait in its result queue, a few records each, as
    # many as the machine's load lets pile up (6 once under a parallel test run)
    args = ["eval", "sequence", str(bag), "--out", str(out), "--workers", "1"]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    assert held.keys() == {"last row", "run over"} and max(held.values()) <= 3, held
    rows = read_rows(out)
    assert len(rows) == n and any(r.flags for r in rows)
    assert odometry_summary(rows) is not None and odometry_summary(rows) in res.output
    for line in failure_summary(rows) + suspect_summary(rows):
        assert line in res.output
    converged = sum(r.result.converged for r in rows)
    assert f"{n} pairs matched with improved: {converged} converged" in res.output


def test_a_runs_columns_are_kept_for_the_run_views_first_opening(tmp_path, intel, monkeypatch):
    """A long run's columns, made as its rows arrived, are cached for its rows file: the run view's
    first opening (``serve --rows``) reads no row, and they equal those of the file read afresh."""
    from mbicp_viz.evaluation import run_rows

    monkeypatch.setenv("MBICP_VIZ_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(run_rows, "CACHED_FROM", 20)  # a long run: 59 rows here
    bag = write(tmp_path / "i.bag", intel_robot(intel, 0, len(intel.scans), MOUNT), "ros1")
    out = tmp_path / "r.jsonl"
    res = CliRunner().invoke(app, ["eval", "sequence", str(bag), "--out", str(out)])
    assert res.exit_code == 0, res.output
    log = read_log(bag)
    with monkeypatch.context() as m:
        m.setattr(run_rows, "file_rows", None)  # no row read: the cache's columns
        cached = run_rows.run_of_log(out, log)
    fresh = run_rows._read(str(out))
    assert len(cached) == len(fresh) == len(intel.scans) - 1
    for name in run_rows.COLUMNS:
        np.testing.assert_array_equal(cached.column(name), fresh.column(name), err_msg=name)
    for k in (0, 17, -1):
        assert cached[k].to_json() == fresh[k].to_json() and cached[k].line == fresh[k].line
