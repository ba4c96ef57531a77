"""Writing a job back as TOML (``optdot design`` writes the job that uses its map).

The job format holds strings, numbers, booleans, arrays of them (nested: profile tables)
and arrays of tables (``[[light_guide.leds]]``); :func:`job_toml` writes exactly those,
and :func:`rebased` rewrites the file paths a job names so they stay right when the job is
written to another directory.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

#: ``(section, key)`` of every value that names a file relative to the job.
PATH_KEYS = (
    ("density", "grid"),
    ("density", "image"),
    ("domain", "outline"),
    ("dots", "diameter_grid"),
    ("design", "target"),
    ("backlight", "other_map"),
)


def rebased(raw: dict[str, Any], old: Path, new: Path) -> dict[str, Any]:
    """A copy of the parsed job ``raw`` whose relative paths, meant from directory
    ``old``, point to the same files from directory ``new``."""
    from ..geometry.outline_io import keep_out_is_wkt

    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in raw.items()}

    def move(p: str) -> str:
        if os.path.isabs(p):
            return p
        return os.path.relpath(os.path.abspath(old / p), os.path.abspath(new))

    for sec, key in PATH_KEYS:
        if isinstance(out.get(sec), dict) and isinstance(out[sec].get(key), str):
            out[sec][key] = move(out[sec][key])
    dom = out.get("domain")
    if isinstance(dom, dict) and isinstance(dom.get("keep_out"), list):
        dom["keep_out"] = [
            move(k) if isinstance(k, str) and not keep_out_is_wkt(k) else k for k in dom["keep_out"]
        ]
    return out


def job_toml(raw: dict[str, Any]) -> str:
    """TOML text of a parsed job (top-level keys, then sections, then arrays of tables)."""
    lines: list[str] = []
    for k, v in raw.items():
        if not isinstance(v, dict):
            lines.append(f"{_key(k)} = {toml_value(v)}")
    for name, sec in raw.items():
        if isinstance(sec, dict):
            _section(lines, name, sec)
    return "\n".join(lines).lstrip("\n") + "\n"


def _section(lines: list[str], name: str, sec: dict[str, Any]) -> None:
    """``[name]`` with its values, then its sub-tables (``[name.k]``) and arrays of tables
    (``[[name.k]]``)."""
    lines += ["", f"[{name}]"]
    tables: dict[str, list[dict[str, Any]]] = {}
    subs: dict[str, dict[str, Any]] = {}
    for k, v in sec.items():
        if isinstance(v, list) and v and all(isinstance(t, dict) for t in v):
            tables[k] = v
        elif isinstance(v, dict):
            subs[k] = v
        else:
            lines.append(f"{_key(k)} = {toml_value(v)}")
    for k, sub in subs.items():
        _section(lines, f"{name}.{_key(k)}", sub)
    for k, rows in tables.items():
        for row in rows:
            lines += ["", f"[[{name}.{_key(k)}]]"]
            lines += [f"{_key(kk)} = {toml_value(vv)}" for kk, vv in row.items()]


def _key(k: str) -> str:
    bare = k.replace("_", "").replace("-", "").isalnum() and k.isascii()
    return k if bare else json.dumps(k)


def toml_value(v: Any) -> str:
    """One TOML value: a string (ASCII, escaped), number, boolean or array of them."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # a TOML basic string
    if isinstance(v, list | tuple):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} into a job")
