"""Parameter files (TOML): read with ``--params``, written by ``mbicp-viz params`` and the debugger.

Keys are the parameter names of the matcher (``Bw``, ``Br``, ``L``, ...), flat or in a table
named after the matcher (``[improved]``); the correlative search's parameters sit in a
``[search]`` table. A field in radians may be given in degrees instead by suffixing its name with
``_deg`` (``Bw_deg = 45``); files written here use that form, since degrees are what people type.
``--params`` also takes the name of a preset shipped in ``mbicp_viz/presets`` (``--params
poor-guess``): the parameter sets the README and docs/ measure, each saying in its comments what
it is for.
"""

from __future__ import annotations

import functools
import math
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from mbicp_viz.core import MATCHERS, ParamError, Params, SearchParams, field_specs
from mbicp_viz.errors import InputError

from .text import opening

SEARCH_TABLE = "search"
MAX_FILE_BYTES = 1_000_000  # a parameter file is a few hundred bytes
PRESETS = Path(__file__).resolve().parent.parent / "presets"


def preset_names() -> list[str]:
    return sorted(p.stem for p in PRESETS.glob("*.toml"))


@functools.cache
def presets_for(algorithm: str) -> dict[str, Params]:
    """The presets that change something of ``algorithm``'s defaults, by name (a preset of other
    matchers only, or with keys this one does not have, is not among them)."""
    default, out = MATCHERS[algorithm].params_type(), {}
    for name in preset_names():
        try:
            params = make_params(algorithm, name)
        except InputError:
            continue
        if params != default:
            out[name] = params
    return out


def params_file(path: str | Path) -> Path:
    """The file ``--params`` names: a path, or else a bare name (no folder, no suffix) of a
    preset."""
    p = Path(path)
    if p.exists() or p.suffix or len(p.parts) > 1:
        return p
    if (PRESETS / f"{p}.toml").is_file():
        return PRESETS / f"{p}.toml"
    raise InputError(
        f"no such file, nor a preset of that name (presets: {', '.join(preset_names())})", str(path)
    )


def _radians(spec, value, path: str | None, where: str) -> float:
    """A ``_deg`` key's value in radians, its bounds checked in the degrees the user typed."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"expected a number of degrees, got {value!r}", path, field=where)
    rad = math.radians(value)
    if spec.lo is not None and rad < spec.lo:
        raise InputError(
            f"{value!r} is below the minimum {math.degrees(spec.lo):g} deg", path, field=where
        )
    if spec.hi is not None and rad > spec.hi:
        raise InputError(
            f"{value!r} is above the maximum {math.degrees(spec.hi):g} deg", path, field=where
        )
    return rad


def params_from_mapping(
    params_type: type, values: dict, path: str | None = None, table: str | None = None
) -> Params:
    """``params_type`` from TOML keys (``_deg`` for radians); errors name the key
    (``table.key``)."""
    return with_values(params_type(), values, path, table)


def with_values(
    params: Params, values: dict, path: str | None = None, table: str | None = None
) -> Params:
    """``params`` with ``values`` over them, named as TOML names them (``_deg`` for radians);
    errors name the key (``table.key``)."""
    specs = {s.name: s for s in field_specs(type(params))}
    kwargs = {}
    for key, value in values.items():
        where = f"{table}.{key}" if table else key
        name = (
            key[:-4]
            if key.endswith("_deg") and specs.get(key[:-4]) and specs[key[:-4]].unit == "rad"
            else key
        )
        if name not in specs:
            raise InputError(f"unknown parameter; known: {', '.join(specs)}", path, field=where)
        if name != key:
            value = _radians(specs[name], value, path, where)
        kwargs[name] = value
    try:
        return replace(params, **kwargs)
    except ParamError as e:
        raise InputError(e.message, path, field=f"{table}.{e.name}" if table else e.name) from None


def read_toml(path: str | Path) -> dict:
    """A TOML file as a dict; every way it can be unreadable is one InputError."""
    p = Path(path)
    with opening(p):
        if p.stat().st_size > MAX_FILE_BYTES:
            raise InputError(f"larger than {MAX_FILE_BYTES} bytes: not a parameter file", str(p))
        data = p.read_bytes()
    try:
        return tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as e:
        raise InputError(f"not UTF-8 text ({e.reason})", str(p)) from None
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"invalid TOML: {e}", str(p)) from None
    except RecursionError:
        raise InputError("invalid TOML: nested too deeply", str(p)) from None


@dataclass(frozen=True)
class ParamsFile:
    """A ``--params`` file, a preset, or none (the defaults), read once: each named matcher's
    parameters and the correlative search's."""

    matchers: dict[str, Params]
    search: SearchParams


def read_params(path: str | Path | None, matchers: Sequence[str]) -> ParamsFile:
    """The parameters of ``matchers`` (defaults, or a file's or preset's) and of the search."""
    for name in matchers:
        if name not in MATCHERS:
            raise InputError(
                f"unknown matcher {name!r}; choose one of {', '.join(MATCHERS)}", field="--algo"
            )
    if path is None:
        return ParamsFile({n: MATCHERS[n].params_type() for n in matchers}, SearchParams())
    path = params_file(path)
    data = read_toml(path)
    return ParamsFile({n: _matcher_table(data, path, n) for n in matchers}, _search(data, path))


def make_params(matcher: str, path: str | Path | None) -> Params:
    """One matcher's parameters: its defaults, or a ``--params`` file's or preset's."""
    return read_params(path, [matcher]).matchers[matcher]


def _matcher_table(data: dict, path: Path, matcher: str) -> Params:
    """A matcher's parameters in a file: its table (``[improved]``), else the flat keys."""
    params_type = MATCHERS[matcher].params_type
    if isinstance(data.get(matcher), dict):
        return params_from_mapping(params_type, data[matcher], str(path), matcher)
    flat = {k: v for k, v in data.items() if not isinstance(v, dict) and k != "algorithm"}
    return params_from_mapping(params_type, flat, str(path))


def _search(data: dict, path: Path) -> SearchParams:
    """The correlative search's parameters: the file's ``[search]`` table, else the defaults."""
    table = data.get(SEARCH_TABLE, {})
    if not isinstance(table, dict):
        raise InputError("expected a table [search]", str(path), field=SEARCH_TABLE)
    return params_from_mapping(SearchParams, table, str(path), SEARCH_TABLE)


def _toml_value(spec, value) -> tuple[str, object, str]:
    """A field as a TOML file names it: key, value and unit (angles in degrees, ``NAME_deg``)."""
    if spec.unit == "rad":
        return f"{spec.name}_deg", math.degrees(value), "deg"
    return spec.name, value, spec.unit


def changed_values(params: Params) -> dict[str, object]:
    """The fields that differ from the matcher's defaults, as a TOML file names them (angles in
    degrees to 12 digits: 50.0, not 50.00000000000001)."""
    default, out = type(params)(), {}
    for s in field_specs(type(params)):
        if getattr(params, s.name) != getattr(default, s.name):
            key, value, unit = _toml_value(s, getattr(params, s.name))
            out[key] = float(f"{value:.12g}") if unit == "deg" else value
    return out


def _lines(params: Params) -> list[str]:
    lines = []
    for s in field_specs(type(params)):
        key, v, unit = _toml_value(s, getattr(params, s.name))
        text = ("true" if v else "false") if isinstance(v, bool) else repr(v)
        lines.append(f"{key} = {text}  # [{unit}] {s.help}")
    return lines


def params_to_toml(params: Params, search: SearchParams | None = None) -> str:
    """A ``--params`` file: the matcher's parameters, then the search's ``[search]`` table."""
    name = next(m.name for m in MATCHERS.values() if type(params) is m.params_type)
    lines = [
        f"# mbicp-viz parameters for {name}; read back with --params FILE",
        f'algorithm = "{name}"',
        *_lines(params),
    ]
    if search is not None:
        lines += [
            "",
            f"[{SEARCH_TABLE}]  # the correlative search (--search, --guess search)",
            *_lines(search),
        ]
    return "\n".join(lines) + "\n"
