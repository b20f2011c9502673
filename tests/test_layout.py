"""The house: the matchers under the project's own import name, every package shipped, and a
command line that loads nothing heavy before a command runs."""

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import mbicp_viz

ROOT = Path(__file__).parent.parent
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]


def test_core_is_mbicp_viz_core_and_never_a_top_level_core(tmp_path):
    # from the checkout's top level, where a folder named core/ sits on sys.path
    res = subprocess.run(
        [sys.executable, "-c", "import core"], cwd=ROOT, capture_output=True, text=True
    )
    assert res.returncode != 0 and "mbicp_viz.core" in res.stderr
    # from anywhere else: there is no top-level core at all
    res = subprocess.run(
        [sys.executable, "-c", "import core"], cwd=tmp_path, capture_output=True, text=True
    )
    assert res.returncode != 0 and "No module named 'core'" in res.stderr
    res = subprocess.run(
        [sys.executable, "-c", "import mbicp_viz.core as c; print(c.Pose2.__module__)"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    assert res.returncode == 0 and res.stdout.strip() == "mbicp_viz.core.se2", res.stderr


def test_every_package_is_shipped_and_the_checkout_maps_them_alike():
    on_disk = {
        ".".join(p.parent.relative_to(ROOT).parts)
        for p in (ROOT / "mbicp_viz").rglob("__init__.py")
    }
    on_disk |= {"mbicp_viz.core"}
    assert on_disk <= set(PYPROJECT["packages"]), on_disk - set(PYPROJECT["packages"])
    mapped = {
        k: v for k, v in PYPROJECT["package-dir"].items() if (ROOT / v / "__init__.py").exists()
    }
    assert mapped == mbicp_viz.CHECKOUT_PACKAGES


def test_the_command_line_loads_nothing_heavy_before_a_command_runs(tmp_path):
    heavy = ("numpy", "scipy", "numba", "rerun", "viser", "matplotlib", "rosbags")
    code = f"import sys, mbicp_viz.cli; print([m for m in {heavy!r} if m in sys.modules])"
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True)
    assert res.returncode == 0 and res.stdout.strip() == "[]", res.stdout + res.stderr


def test_every_command_answers_help(tmp_path):
    from typer.testing import CliRunner

    from mbicp_viz.cli import app
    from mbicp_viz.cli.bench import command_names

    names = command_names(app)
    assert {"match", "serve", "eval sequence", "bench startup", "params"} <= set(names)
    shown = 0
    for name in names:
        res = CliRunner().invoke(app, [*name.split(), "--help"], terminal_width=400)
        assert res.exit_code == 0 and "Usage" in res.output and "<bool>" not in res.output, (
            name,
            res.output,
        )
        # units and table names in brackets ("[m]", "[deg]", "a [search] table") are shown as
        # written, not
        # taken for markup and dropped
        for param in _command(app, name).params:
            # a metavar names as many values as the option takes (X Y THETA_DEG: three)
            if param.metavar is not None and param.nargs > 0:
                assert len(param.metavar.split()) == param.nargs, (name, param.name, param.metavar)
            for bracket in re.findall(r"\[[^\]]*\]", getattr(param, "help", None) or ""):
                assert bracket in res.output, (name, param.name, bracket)
                shown += 1
    assert shown >= 10


def test_every_command_that_reads_scans_can_choose_the_stream():
    """A bag with two scan topics is refused until one is named, and a CARMEN log with two laser
    message types reads its front laser unless another is named: every command that reads scan
    files must let the user name it (--topic)."""
    from mbicp_viz.cli import app
    from mbicp_viz.cli.bench import command_names

    reading = 0
    for name in command_names(app):
        command = _command(app, name)
        arguments = {p.name for p in command.params if p.param_type_name == "argument"}
        if arguments & {"first", "log", "logs", "scans"}:
            reading += 1
            assert any(
                "--topic" in p.opts for p in command.params if p.param_type_name == "option"
            ), name
    assert reading >= 14


def _command(app, name: str):
    """The click command of ``name`` ("eval sequence"), with its parameters."""
    import typer

    command = typer.main.get_command(app)
    for part in name.split():
        command = command.commands[part]
    return command
