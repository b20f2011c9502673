"""Parameter files (TOML): read with ``--params``, written by ``mbicp-viz params`` and the GUI.

Keys are the parameter names of the matcher (``Bw``, ``Br``, ``L``, ...). A field in radians
may be given in degrees instead by suffixing its name with ``_deg`` (``Bw_deg = 45``); files
written here use that form, since degrees are what people type.
"""

from __future__ import annotations

import math
import tomllib

from core import MATCHERS, ParamError, Params, field_specs

from .errors import InputError


def params_from_mapping(algorithm: str, values: dict, path: str | None = None) -> Params:
    m = MATCHERS[algorithm]
    specs = {s.name: s for s in field_specs(m.params_type)}
    kwargs = {}
    for key, value in values.items():
        name = key[:-4] if key.endswith("_deg") and specs.get(key[:-4]) and specs[key[:-4]].unit == "rad" else key
        if name not in specs:
            raise InputError(f"unknown parameter for {algorithm}; known: {', '.join(specs)}", path, field=key)
        if name != key:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InputError(f"expected a number of degrees, got {value!r}", path, field=key)
            value = math.radians(value)
        kwargs[name] = value
    try:
        return m.params_type(**kwargs)
    except ParamError as e:
        raise InputError(str(e).split(": ", 1)[1], path, field=e.name) from None


def load_params(path: str, algorithm: str) -> Params:
    """Parameters for ``algorithm`` from a TOML file (flat keys, or a table named after the algorithm)."""
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise InputError("no such file", path) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise InputError(f"invalid TOML: {e}", path) from None
    if algorithm in data and isinstance(data[algorithm], dict):
        data = data[algorithm]
    else:
        data = {k: v for k, v in data.items() if not isinstance(v, dict) and k != "algorithm"}
    return params_from_mapping(algorithm, data, path)


def params_to_toml(params: Params) -> str:
    name = next(m.name for m in MATCHERS.values() if type(params) is m.params_type)
    lines = [f"# mbicp-viz parameters for {name}; read back with --params FILE", f'algorithm = "{name}"']
    for s in field_specs(type(params)):
        v = getattr(params, s.name)
        key, unit = s.name, s.unit
        if s.unit == "rad":
            key, v, unit = f"{s.name}_deg", math.degrees(v), "deg"
        text = ("true" if v else "false") if isinstance(v, bool) else repr(v)
        lines.append(f"{key} = {text}  # [{unit}] {s.help}")
    return "\n".join(lines) + "\n"
