"""What a QA result is a result of: the sign-off sheet's traceability block.

A report that goes to tooling must say which pattern it judged, against which job, made by
which optdot: the optdot version, the date, the job file and every file it reads (path and
SHA-256), the seed, and the judged pattern file (SHA-256; a dataset by its manifest, which
holds every part's checksum). The date is now, in UTC, or ``SOURCE_DATE_EPOCH`` when set
(the reproducible-builds convention), so that a rerun can give the same bytes.
"""

from __future__ import annotations

import datetime
import hashlib
import os
from pathlib import Path
from typing import Any

from ..files import sha256_file


def sha256_of(path: str | Path) -> str | None:
    """SHA-256 of a file (a dataset directory: of its manifest), or None if unreadable."""
    p = Path(path)
    if p.is_dir():
        p = p / "_manifest.json"
    try:
        return sha256_file(p)
    except OSError:
        return None


def version() -> str:
    """The installed optdot's version ("unknown" when run from a bare checkout)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as _version

    try:
        return _version("optdot")
    except PackageNotFoundError:
        return "unknown"


def now_utc() -> str:
    """ISO 8601 UTC time of the report: ``SOURCE_DATE_EPOCH`` when set, else now."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    try:
        t = datetime.datetime.fromtimestamp(int(epoch), datetime.UTC) if epoch else None
    except (ValueError, OverflowError, OSError):
        t = None
    t = t or datetime.datetime.now(datetime.UTC)
    return t.replace(microsecond=0).isoformat().replace("+00:00", "Z")


def mask_lines(prov: dict[str, Any]) -> tuple[str, ...]:
    """The provenance a mask carries (``"key: value"``, each under 126 bytes, GDSII's
    property limit). The first line, ``provenance: optdot 0.2.0 seed 1 sha256:<digest>``,
    fits where only one does (GDSII: 128 bytes per element); the digest is the SHA-256 of
    the lines after it, which name the job, its inputs and the judged pattern by file
    name and SHA-256, and it is in the QA report too (``provenance.mask_digest``). No date
    and no directories: the same job and seed give the same mask bytes wherever and
    whenever they run."""
    lines = [f"optdot: {prov.get('optdot')}"]
    if prov.get("seed") is not None:
        lines.append(f"seed: {prov['seed']}")

    def named(key: str, e) -> None:
        if e and e.get("sha256"):
            lines.append(f"{key}: {Path(e['path']).name[:40]} sha256:{e['sha256']}")

    named("job", prov.get("job"))
    for e in prov.get("inputs", []):
        named("input", e)
    named("pattern", prov.get("pattern"))
    digest = hashlib.sha256("\n".join(lines).encode()).hexdigest()
    head = f"provenance: optdot {prov.get('optdot')} seed {prov.get('seed')} sha256:{digest}"
    return (head[:126], *lines)


def mask_digest(prov: dict[str, Any]) -> str:
    """The digest a mask's first provenance line carries (see :func:`mask_lines`)."""
    return mask_lines(prov)[0].rsplit("sha256:", 1)[1]


def provenance(
    job_file: Path | None,
    inputs: tuple[Path, ...],
    pattern_path: str | Path | None,
    seed: int | None,
) -> dict[str, Any]:
    """The traceability block of a QA result.

    Args:
        job_file: the job file judged against, or None.
        inputs: every file the job reads (the job file among them or not).
        pattern_path: the file (or dataset) judged, or None for a pattern in memory.
        seed: the seed that made the pattern, when known.

    Returns:
        ``{"optdot", "date_utc", "seed", "pattern": {"path", "sha256"} | None, "job":
        {"path", "sha256"} | None, "inputs": [{"path", "sha256"}]}``.
    """

    def entry(p) -> dict[str, Any]:
        return {"path": str(p), "sha256": sha256_of(p)}

    source = job_file
    read = [entry(p) for p in inputs if Path(p) != source]
    out = {
        "optdot": version(),
        "date_utc": now_utc(),
        "seed": seed,
        "pattern": entry(pattern_path) if pattern_path else None,
        "job": entry(source) if source else None,
        "inputs": read,
    }
    out["mask_digest"] = mask_digest(out)
    return out
