"""Mutation fuzzing of the real files every reader takes: truncations, byte flips, lines deleted or
repeated, counts and tokens changed, NaN, inf and numbers beyond a float, damaged compression and
bag chunks, pickled and complex arrays. Every input ends in one clean error or in scans that keep
the invariants; a record whose field count a mutation changed is always an error."""

import gzip
import io
import math
import shutil
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mbicp_viz.core import MATCHERS, Pose2
from mbicp_viz.core.scan import ABSURD_RANGE_M
from mbicp_viz.errors import InputError
from mbicp_viz.readers import read_log
from mbicp_viz.readers.log import MIN_BEARING_STEP_RAD
from mbicp_viz.readers.relations import read_relations

from .bags import intel_robot, write
from .conftest import DATA, EXAMPLES, INTEL

TEXT_FILES = {
    "carmen.log": DATA / "intel-relations.log",
    "laserazos.log": DATA / "laserazosSM3-40.log",
    "datos.off": DATA / "datos.off",
    "blocks.off": DATA / "laserazosSM3-6.off",
    "stallo2.jsonl": DATA / "stallo2.jsonl",
}
NUMBERS = [
    "nan",
    "inf",
    "-inf",
    "1e400",
    "-1e308",
    "1e150",
    "0",
    "-1",
    "1e-300",
    "99999999999",
    "x",
    "",
    "1" + "0" * 400,
]
FUZZ = settings(
    max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


def invariants(log) -> None:
    """What every scan a reader returns satisfies."""
    assert log.scans
    for s in log.scans:
        assert np.all(np.isfinite(s.points())) and s.n_valid > 0
        assert np.all(np.diff(s.bearings) >= MIN_BEARING_STEP_RAD)
        assert s.bearings[-1] - s.bearings[0] < 2 * math.pi
        assert np.all(s.ranges[s.valid] < ABSURD_RANGE_M) and np.all(s.ranges[s.valid] > 0)


def read(path):
    """The log, or None after one clean error line."""
    try:
        log = read_log(path)
        invariants(log)  # a bag read through its index reads its scans here: damage is met here
    except InputError as e:
        assert str(e) and "\n" not in str(e) and str(path.name) in str(e)
        return None
    return log


@st.composite
def text_mutation(draw):
    name = draw(st.sampled_from(sorted(TEXT_FILES)))
    lines = TEXT_FILES[name].read_text().split("\n")
    i = draw(st.integers(0, max(len(lines) - 2, 0)))
    toks = lines[i].split()
    kind = draw(
        st.sampled_from(["truncate", "delete", "repeat", "number", "drop", "add", "count", "flip"])
    )
    changes_fields = False
    if kind == "truncate":
        text = "\n".join(lines)
        text = text[: draw(st.integers(0, len(text) - 1))]
    elif kind == "flip":
        b = bytearray("\n".join(lines).encode())
        b[draw(st.integers(0, len(b) - 1))] = draw(st.integers(0, 255))
        text = b.decode("latin-1")
    else:
        if kind == "delete":
            del lines[i]
        elif kind == "repeat":
            lines.insert(i, lines[i])
        elif toks and kind == "number":
            toks[draw(st.integers(0, len(toks) - 1))] = draw(st.sampled_from(NUMBERS))
        elif toks and kind == "drop":
            del toks[draw(st.integers(0, len(toks) - 1))]
            changes_fields = True
        elif toks and kind == "add":
            toks.insert(draw(st.integers(0, len(toks))), draw(st.sampled_from(["1.5", "0", "nan"])))
            changes_fields = True
        elif len(toks) > 1 and kind == "count":
            new = draw(st.sampled_from(["0", "1", "179", "181", "100001", "-5"]))
            changes_fields = new != toks[1]
            toks[1] = new
        if kind in ("number", "drop", "add", "count") and toks:
            lines[i] = " ".join(toks)
        text = "\n".join(lines)
    fixed = (
        name.endswith(".log")
        and lines
        and lines[min(i, len(lines) - 1)].split()[:1] in (["FLASER"], ["ODOM"])
    )
    return name, text, kind, changes_fields and fixed


@FUZZ
@given(case=text_mutation())
def test_text_readers_on_mutated_real_files(tmp_path, case):
    name, text, kind, changed_layout = case
    path = tmp_path / name
    path.write_bytes(text.encode("latin-1", "replace"))
    log = read(path)
    # a FLASER or ODOM record with a field too many or too few: never read as another
    if changed_layout:
        assert log is None, (kind, text[:200])


@FUZZ
@given(
    cut=st.floats(0.0, 0.999),
    flips=st.lists(st.tuples(st.floats(0, 0.999), st.integers(0, 255)), max_size=6),
    inner=st.booleans(),
)
def test_damaged_gzip(tmp_path, cut, flips, inner):
    data = (DATA / "aces-10.log.gz").read_bytes()
    if inner:  # damage inside the compressed stream, keeping its header
        b = bytearray(data)
        for at, v in flips:
            b[10 + int(at * (len(b) - 10))] = v
        data = bytes(b)
    else:
        data = data[: int(cut * len(data))]
    path = tmp_path / "aces.log.gz"
    path.write_bytes(data)
    read(path)


def npz_bytes(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


@FUZZ
@given(
    mutation=st.sampled_from(["flip", "cut", "complex", "object", "shape", "nan_bearings", "huge"]),
    at=st.floats(0, 0.999),
    value=st.integers(0, 255),
)
def test_damaged_npz(tmp_path, mutation, at, value):
    with np.load(EXAMPLES / "hokuyo-125-130.npz") as z:
        ranges, bearings = z["ranges"], z["bearings"]
    data = {
        "flip": None,
        "cut": None,
        "complex": npz_bytes(ranges=ranges.astype(complex), bearings=bearings),
        "object": npz_bytes(ranges=np.array([ranges[0], "x"], dtype=object), bearings=bearings),
        "shape": npz_bytes(ranges=ranges, bearings=bearings[..., :-3]),
        "nan_bearings": npz_bytes(
            ranges=ranges, bearings=np.where(np.arange(bearings.shape[-1]) == 5, np.nan, bearings)
        ),
        "huge": npz_bytes(ranges=ranges * 1e150, bearings=bearings),
    }[mutation]
    if data is None:
        raw = bytearray((EXAMPLES / "hokuyo-125-130.npz").read_bytes())
        if mutation == "flip":
            raw[int(at * len(raw))] = value
        else:
            raw = raw[: int(at * len(raw))]
        data = bytes(raw)
    path = tmp_path / "s.npz"
    path.write_bytes(data)
    log = read(path)
    assert mutation not in ("complex", "object", "shape", "nan_bearings", "huge") or log is None


@pytest.fixture(scope="module")
def small_bag(tmp_path_factory, intel):
    return write(
        tmp_path_factory.mktemp("bag") / "small.bag",
        intel_robot(intel, 10, 12, Pose2(0.1, 0.0, 0.0)),
        "ros1",
    ).read_bytes()


@FUZZ
@given(
    cut=st.floats(0.0, 1.0),
    flips=st.lists(st.tuples(st.floats(0, 0.999), st.integers(0, 255)), max_size=8),
)
def test_damaged_bags(tmp_path, small_bag, cut, flips):
    b = bytearray(small_bag[: int(cut * len(small_bag))] if not flips else small_bag)
    for at, v in flips:
        b[int(at * len(b))] = v
    path = tmp_path / "damaged.bag"
    path.write_bytes(bytes(b))
    log = read(path)
    if log is not None and len(log.scans) >= 2:  # what survives still matches without a traceback
        MATCHERS["improved"].run(
            log.scans[0], log.scans[1], Pose2(), MATCHERS["improved"].params_type()
        )


@pytest.fixture(scope="module", params=["mcap", "humble"])
def small_ros2(tmp_path_factory, intel, request):
    """A ROS 2 bag folder (MCAP, sqlite3), its storage file's name and bytes."""
    folder = write(
        tmp_path_factory.mktemp(request.param) / "small",
        intel_robot(intel, 10, 12, Pose2(0.1, 0.0, 0.0)),
        request.param,
    )
    (file,) = (f for f in folder.iterdir() if f.suffix in (".mcap", ".db3"))
    return folder, file.name, file.read_bytes()


@FUZZ
@given(
    cut=st.floats(0.0, 1.0),
    flips=st.lists(st.tuples(st.floats(0, 0.999), st.integers(0, 255)), max_size=8),
    near_end=st.booleans(),
)
def test_damaged_ros2_bags(tmp_path, small_ros2, cut, flips, near_end):
    """A ROS 2 bag's storage file cut short or with bytes flipped, anywhere or in its last
    kilobyte (MCAP's summary: chunk indexes, channels; its message indexes sit after each
    chunk): one clean error or scans that keep the invariants and still match."""
    folder, name, data = small_ros2
    b = bytearray(data[: int(cut * len(data))] if not flips else data)
    start = max(len(b) - 1024, 0) if near_end else 0
    for at, v in flips:
        b[start + int(at * (len(b) - start))] = v
    damaged = tmp_path / "damaged"
    shutil.copytree(folder, damaged, dirs_exist_ok=True)
    (damaged / name).write_bytes(bytes(b))
    log = read(damaged)
    if log is not None and len(log.scans) >= 2:
        MATCHERS["improved"].run(
            log.scans[0], log.scans[1], Pose2(), MATCHERS["improved"].params_type()
        )


@pytest.fixture(scope="module")
def small_bag_scans(tmp_path_factory, small_bag):
    path = tmp_path_factory.mktemp("bag") / "intact.bag"
    path.write_bytes(small_bag)
    return read_log(path).scans


def outside_chunk_data(bag: bytes) -> list[tuple[int, int]]:
    """The byte ranges of a ROS 1 bag that are not messages: every record's header, and whole
    the records that are index (bag header, index data after each chunk, connections, chunk
    infos); a chunk's data only its header."""
    from mbicp_viz.readers.ros1_format import MAGIC, OP_CHUNK, header, op_of

    out, pos = [], len(MAGIC)
    while pos + 4 <= len(bag):
        hlen = int.from_bytes(bag[pos : pos + 4], "little")
        dlen = int.from_bytes(bag[pos + 4 + hlen : pos + 8 + hlen], "little")
        chunk = op_of(header(bag[pos + 4 : pos + 4 + hlen], "bag")) == OP_CHUNK
        out.append((pos, pos + 8 + hlen + (0 if chunk else dlen)))
        pos += 8 + hlen + dlen
    return out


@FUZZ
@given(
    flips=st.lists(
        st.tuples(st.integers(0, 10**6), st.floats(0, 0.999), st.integers(0, 255)),
        min_size=1,
        max_size=4,
    )
)
def test_a_damaged_index_gives_the_bags_scans_or_says_what_it_lost(
    tmp_path, small_bag, small_bag_scans, flips
):
    """Bytes of the index flipped (where a bag read through its index is read, not its
    messages): one clean error, or the bag's own scans, or fewer with a note saying what was
    lost; never other scans, silently."""
    regions, b = outside_chunk_data(small_bag), bytearray(small_bag)
    for which, at, value in flips:
        start, end = regions[which % len(regions)]
        b[start + int(at * (end - start))] = value
    path = tmp_path / "damaged.bag"
    path.write_bytes(bytes(b))
    log = read(path)
    if log is not None:
        same = len(log.scans) == len(small_bag_scans) and all(
            a.stamp == c.stamp and np.array_equal(a.ranges, c.ranges, equal_nan=True)
            for a, c in zip(log.scans, small_bag_scans)
        )
        assert same or log.notes, log.notes


@FUZZ
@given(line=st.lists(st.sampled_from(NUMBERS + ["1.0", "2.5", "#", "0.1"]), max_size=10))
def test_relations_records_hold_exactly_eight_numbers(tmp_path, line):
    path = tmp_path / "r.relations"
    path.write_text(" ".join(line) + "\n")
    try:
        rels = read_relations(str(path))
    except InputError as e:
        assert "\n" not in str(e)
        return
    tokens = " ".join(line).split("#")[0].split()
    assert len(tokens) == 8 and all(math.isfinite(float(t)) for t in tokens) and len(rels) == 1


def test_hostile_files_that_are_no_data(tmp_path):
    (tmp_path / "dir.log").mkdir()
    assert read(tmp_path / "dir.log") is None
    zero = tmp_path / "zero.log"
    # a line that never ends: refused at the cap, not read whole
    zero.write_bytes(b"\0" * 9_000_000)
    assert read(zero) is None
    bomb = tmp_path / "bomb.npz"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("ranges.npy", b"\0" * 600_000_000)
    assert read(bomb) is None
    gz = tmp_path / "flat.log.gz"
    gz.write_bytes(gzip.compress(INTEL.read_bytes()[:100]))  # a gzipped gzip: not text
    assert read(gz) is None
