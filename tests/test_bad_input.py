"""Bad input: one readable line naming file, line and field; exit code 2; never a traceback."""

import gzip
import math
import pickle

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.core import Scan, ScanError, make_scan
from mbicp_viz.errors import InputError
from mbicp_viz.readers import read_log

from .conftest import INTEL

runner = CliRunner()
FLASER_OK = "FLASER 3 1.0 1.1 1.2 0 0 0 0 0 0 1.0 host 1.0"


def run(*args):
    res = runner.invoke(app, [str(a) for a in args])
    return res.exit_code, res.output


def assert_clean_error(code, out, *needles):
    assert code == 2, out
    assert "Traceback" not in out
    lines = [ln for ln in out.strip().splitlines() if ln]
    assert len(lines) == 1 and lines[0].startswith("mbicp-viz: error:"), out
    for n in needles:
        assert n in lines[0], (n, lines[0])


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    "body, needles",
    [
        # malformed number
        (
            "FLASER 3 1.0 x 1.2 0 0 0 0 0 0 1 h 1\n",
            ["bad.log:1", "range[1]", "'x'"],
        ),
        ("# ok\n12.5 abc\n", ["bad.log:2", "message"]),  # not a message at all
        # wrong beam count
        (
            "FLASER 5 1.0 1.1 1.2\n",
            ["bad.log:1", "num_readings", "5 ranges announced"],
        ),
        # all invalid
        (
            "FLASER 3 0 nan inf 0 0 0 0 0 0 1 h 1\n",
            ["bad.log:1", "scan 0", "no valid reading"],
        ),
        ("FLASER 3 1 1 1 nan 0 0 0 0 0 1 h 1\n", ["bad.log:1", "laser_pose_x"]),  # NaN pose
        ("ODOM 1 2\n", ["bad.log:1", "odom_theta"]),
        ("NEFF 15\n", ["bad.log", "no laser scans"]),  # only unknown (skipped) messages: empty log
        ("", ["bad.log", "no laser scans"]),  # empty file
    ],
)
def test_carmen_errors_name_file_line_field(tmp_path, body, needles):
    p = write(tmp_path, "bad.log", body)
    assert_clean_error(*run("match", p, "--pair", 0, 1), *needles)


def test_missing_file():
    assert_clean_error(
        *run("match", "no/such/file.log", "--pair", 0, 1), "no/such/file.log", "no such file"
    )


def test_unknown_suffix(tmp_path):
    p = write(tmp_path, "scan.xyz", "1 2 3")
    assert_clean_error(*run("match", p, p), "unknown file type")


def test_pair_out_of_range():
    assert_clean_error(*run("match", INTEL, "--pair", 0, 999), "out of range", "60 scans")


def test_nan_and_unknown_parameters(tmp_path):
    p = write(tmp_path, "p.toml", "Br = nan\n")
    assert_clean_error(
        *run("match", INTEL, "--pair", 0, 1, "--params", p), "p.toml", "Br", "finite"
    )
    p = write(tmp_path, "p.toml", "Bw_deg = -5\n")
    assert_clean_error(
        *run("match", INTEL, "--pair", 0, 1, "--params", p), "Bw", "below the minimum"
    )
    p = write(tmp_path, "p.toml", "[improved]\nextrapolate = -1\n")
    code, out = run("match", INTEL, "--pair", 0, 1, "--params", p)
    assert_clean_error(code, out, "improved.extrapolate", "below the minimum 0.0")
    assert out.strip().endswith("minimum 0.0")  # a ratio: no unit to name after the bound
    p = write(tmp_path, "p.toml", "bogus = 1\n")
    assert_clean_error(
        *run("match", INTEL, "--pair", 0, 1, "--params", p), "bogus", "unknown parameter"
    )
    p = write(tmp_path, "p.toml", "Br = [1\n")
    assert_clean_error(*run("match", INTEL, "--pair", 0, 1, "--params", p), "invalid TOML")


def test_nan_initial_guess():
    assert_clean_error(
        *run("match", INTEL, "--pair", 0, 1, "--init", "nan", 0, 0), "--init X", "finite"
    )


def test_unknown_algorithm():
    assert_clean_error(
        *run("match", INTEL, "--algo", "sift"), "--algo", "'sift' is not one of 'icp'"
    )


@pytest.mark.parametrize(
    "args, field, needle",
    [
        (("eval", "overlap", INTEL, "--scans", "1,x"), "--scans", "expected numbers"),
        (("eval", "overlap", INTEL, "--ratios", "100,sixty"), "--ratios", "expected numbers"),
        (
            ("eval", "basin", INTEL, "--pair", 0, 1, "--thetas-deg=a"),
            "--thetas-deg",
            "expected numbers",
        ),
        (("eval", "basin", INTEL, "--pair", 0, 1, "--thetas-deg=0,inf"), "--thetas-deg", "finite"),
        (("compare", INTEL, "--pair", 0, 1, "--truth", "nan", 0, 0), "--truth X", "finite"),
        (("compare", INTEL, "--pair", 0, 1, "--algos", ","), "--algos", "at least one matcher"),
        (("eval", "ceiling", INTEL, "--algos", " "), "--algos", "at least one matcher"),
        (("eval", "overlap", INTEL, "--algos", ",,"), "--algos", "at least one matcher"),
    ],
)
def test_lists_of_numbers_and_matchers(args, field, needle):
    assert_clean_error(*run(*args), field, needle)


@pytest.mark.parametrize(
    "args, option",
    [
        (("eval", "overlap", INTEL, "--max-xy", "inf"), "--max-xy"),
        (("eval", "protocol", INTEL, "--max-xy", "nan"), "--max-xy"),
        (("eval", "basin", INTEL, "--pair", 0, 1, "--range-xy", "inf"), "--range-xy"),
        (("eval", "relations", INTEL, INTEL, "--offset", "nan"), "--offset"),
        (("eval", "relations", INTEL, INTEL, "--tolerance", "inf"), "--tolerance"),
        (("eval", "protocol", INTEL, "--seed", "-1"), "--seed"),
    ],
)
def test_numeric_options_out_of_their_domain(args, option):
    """Checked by the command line parser (typer's own message, exit 2), before any work."""
    code, out = run(*args)
    assert code == 2 and "Traceback" not in out
    assert f"Invalid value for '{option}'" in out, out


def test_overlap_protocol_choices():
    assert_clean_error(
        *run("eval", "overlap", INTEL, "--thin", "both"), "--thin", "'reference', 'object'"
    )
    assert_clean_error(
        *run("eval", "overlap", INTEL, "--removal", "holes"), "--removal", "'block', 'random'"
    )


@pytest.mark.parametrize(
    "args",
    [
        ("match", INTEL, "--pair", 0, 1, "--rrd"),
        ("compare", INTEL, "--pair", 0, 1, "--rrd"),
        ("eval", "overlap", INTEL, "--csv"),
        ("eval", "overlap", INTEL, "--png"),
        ("eval", "sequence", INTEL, "--tum"),
        ("eval", "basin", INTEL, "--pair", 0, 1, "--png"),
        ("params", "--out"),
    ],
)
def test_an_unwritable_output_is_refused_before_the_work(tmp_path, args):
    """A missing folder or a folder given as the file: a clean error up front, not a traceback
    after the whole run."""
    missing = tmp_path / "no-such-folder" / "out.x"
    extra = ("--out", tmp_path / "rows.json") if args[:2] == ("eval", "sequence") else ()
    assert_clean_error(*run(*args, missing, *extra), args[-1], "does not exist")
    assert_clean_error(*run(*args, tmp_path, *extra), args[-1], "is a folder")
    assert not (tmp_path / "rows.json").exists()


def test_record_makes_its_output_folder(tmp_path):
    out = tmp_path / "a" / "b"
    code, text = run("record", "large-rotation", "--out-dir", out)
    assert code == 0, text
    assert (out / "large-rotation.rrd").stat().st_size > 0
    (tmp_path / "file").write_text("")
    assert_clean_error(
        *run("record", "large-rotation", "--out-dir", tmp_path / "file" / "x"),
        "--out-dir",
        "cannot make folder",
    )


def test_csm_json_errors(tmp_path):
    p = write(tmp_path, "s.jsonl", '{"nrays": 3, "theta": [0, 1], "readings": [1, 2, 3]}\n')
    assert_clean_error(*run("match", p, p), "s.jsonl:1", "theta")
    p = write(tmp_path, "s.jsonl", '{"nrays": 3, \n')
    assert_clean_error(*run("match", p, p), "s.jsonl:1", "invalid JSON")


def test_bag_with_other_message_type(tmp_path):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    String = store.types["std_msgs/msg/String"]
    path = tmp_path / "strings.bag"
    with Writer(path) as w:
        c = w.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        w.write(c, 1, store.serialize_ros1(String(data="hi"), "std_msgs/msg/String"))
    assert_clean_error(*run("match", path, path), "strings.bag", "no sensor_msgs/msg/LaserScan")


def test_gzip_truncated(tmp_path):
    data = gzip.compress(INTEL.read_bytes()[:0] + b"FLASER 3 1 1 1 0 0 0 0 0 0 1 h 1\n" * 200)
    p = tmp_path / "t.log.gz"
    p.write_bytes(data[: len(data) // 2])
    assert_clean_error(*run("match", p, "--pair", 0, 1), "t.log.gz")


def test_scan_with_nan_and_inf_masks_them():
    s = make_scan([1.0, np.nan, np.inf, -1.0, 0.0, 2.0], np.linspace(-1, 1, 6))
    assert s.valid.tolist() == [True, False, False, False, False, True]
    assert np.all(np.isfinite(s.points()))
    with pytest.raises(ScanError, match="no valid reading"):
        make_scan([np.nan, np.inf], [0.0, 0.1])
    with pytest.raises(ScanError, match="empty"):
        make_scan([], [])
    with pytest.raises(ScanError, match="increasing"):
        make_scan([1.0, 1.0], [0.1, 0.0])


# Fuzzing: every reader sees random bytes and random lines, and only ever returns scans or
# InputError.
SUFFIXES = [".log", ".off", ".jsonl", ".scans", ".npz", ".bag", ".log.gz"]
token = st.sampled_from(
    [
        "FLASER",
        "ODOM",
        "PARAM",
        "ROBOTLASER1",
        "RAWLASER1",
        "NEFF",
        "3",
        "0",
        "1.5",
        "-2",
        "nan",
        "inf",
        "x",
        "{",
        "}",
        '"nrays":',
        "[",
        "]",
        ",",
        "null",
        "8.19",
        "81.9",
        "#",
        "1e400",
    ]
)
line = st.lists(token, max_size=14).map(" ".join)


def check_reader(path):
    try:
        log = read_log(path)
    except InputError as e:
        assert str(e) and "\n" not in str(e)
        return
    assert len(log.scans) > 0
    for s in log.scans:
        assert isinstance(s, Scan) and s.n_valid > 0
        assert np.all(np.isfinite(s.points()))


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(suffix=st.sampled_from(SUFFIXES), data=st.binary(max_size=400))
def test_random_bytes_never_crash_a_reader(tmp_path, suffix, data):
    p = tmp_path / f"fuzz{suffix}"
    p.write_bytes(data)
    check_reader(p)


@settings(
    max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    suffix=st.sampled_from([".log", ".off", ".jsonl", ".scans"]), lines=st.lists(line, max_size=6)
)
def test_random_lines_never_crash_a_reader(tmp_path, suffix, lines):
    p = tmp_path / f"fuzz{suffix}"
    p.write_text("\n".join(lines) + "\n")
    check_reader(p)


def test_fuzz_check_accepts_a_valid_line(tmp_path):
    # the fuzz oracle is not vacuous: a valid line reads as a scan
    p = write(tmp_path, "ok.log", FLASER_OK + "\n")
    assert len(read_log(p)) == 1 and math.isclose(read_log(p).scans[0].ranges[0], 1.0)


def _refuse(scan: Scan) -> None:
    raise ScanError(scan.source, "refused in a worker")


def test_errors_raised_in_worker_processes_arrive_whole():
    """Evaluations run in a process pool, which sends exceptions back pickled: each error type
    must rebuild with its fields, else the user gets BrokenProcessPool instead of the message."""
    from mbicp_viz.core import ParamError
    from mbicp_viz.evaluation.pool import ordered_map

    for e in (
        ScanError(read_log(INTEL).scans[0].source, "why"),
        ParamError("Br", "must be > 0"),
        InputError("bad value", "a.log", 3, "ranges"),
    ):
        back = pickle.loads(pickle.dumps(e))
        assert type(back) is type(e) and str(back) == str(e) and vars(back) == vars(e)
    scans = read_log(INTEL).scans[:4]
    with pytest.raises(ScanError, match="scan 0.*refused in a worker"):
        ordered_map(_refuse, scans, workers=2)


def test_a_key_holding_a_newline_is_named_on_one_line(tmp_path):
    """A parameter file's key is the user's text: one holding a control character is quoted and
    escaped, so the error stays one line (the rows-file fuzzer found such a key)."""
    params = write(tmp_path, "p.toml", '"mad_\\nanneal" = 1.0\n')
    code, out = run("match", INTEL, "--pair", 0, 1, "--params", params)
    assert_clean_error(code, out, "p.toml", "'mad_\\nanneal': unknown parameter")
