"""What a DXF's modelspace draws, in millimetres: drawing units and block references.

Two facts of a DXF change every coordinate in it and are easy to miss:

- **Units.** ``$INSUNITS`` names the drawing unit (1 inch, 4 mm, 5 cm, 6 m, 13 µm, ...);
  a panel drawn in inches is 25.4 times larger in mm. :func:`mm_per_unit` gives the factor
  (0 = unitless and a missing header, as in R12, are taken as mm, the CAD convention for
  optical parts; a code with no length, such as 'light years' or a garbage value, is
  refused with the unit named).
- **Block references.** A hole or a set of dots drawn once as a block and placed by
  INSERT (or MINSERT, a grid of them) is where its transform puts it: moved, rotated,
  scaled, mirrored, nested. :func:`drawn_entities` expands them into virtual entities in
  world coordinates (ezdxf's own transforms), entities on layer ``0`` taking the layer of
  the reference that places them, as CAD programs show them. Nesting is bounded (a block
  referring to itself is refused) and so is the number of entities an expansion may
  produce (a 3000 × 3000 MINSERT of a small file would otherwise fill the memory).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from ..errors import GeometryError, one_line

#: Deepest nesting of block references followed.
MAX_DEPTH = 16
#: Most entities one file may expand to (references included).
MAX_ENTITIES = 20_000_000

#: ``$INSUNITS`` codes with a length: code -> (name, mm per unit).
UNITS: dict[int, tuple[str, float]] = {
    1: ("inches", 25.4),
    2: ("feet", 304.8),
    3: ("miles", 1609344.0),
    4: ("millimeters", 1.0),
    5: ("centimeters", 10.0),
    6: ("meters", 1000.0),
    7: ("kilometers", 1e6),
    8: ("microinches", 25.4e-6),
    9: ("mils", 25.4e-3),
    10: ("yards", 914.4),
    11: ("angstroms", 1e-7),
    12: ("nanometers", 1e-6),
    13: ("microns", 1e-3),
    14: ("decimeters", 100.0),
    15: ("decameters", 1e4),
    16: ("hectometers", 1e5),
    17: ("gigameters", 1e12),
}


def mm_per_unit(doc, path: str | Path) -> float:
    """Millimetres per drawing unit of ``doc`` (its ``$INSUNITS``).

    Raises:
        GeometryError: a unit code with no length (astronomical units, parsecs, ...) or
            not a unit at all; the message names it.
    """
    code = doc.header.get("$INSUNITS", 0)
    try:
        code = int(code)
    except (TypeError, ValueError):
        raise GeometryError(f"{path}: $INSUNITS = {code!r} is not a unit code") from None
    if code == 0:
        return 1.0
    if code not in UNITS:
        raise GeometryError(
            f"{path}: $INSUNITS = {code} is not a length optdot converts "
            "(inches, feet, mm, cm, m, µm, mils, ...); save the drawing in mm"
        )
    return UNITS[code][1]


def drawn_entities(layout, path: str | Path) -> Iterator:
    """Every entity ``layout`` draws, block references expanded into world coordinates.

    Yields:
        ezdxf entities (virtual ones for the contents of blocks); an entity of a block on
        layer ``0`` carries the layer of the reference that placed it.

    Raises:
        GeometryError: references nested deeper than :data:`MAX_DEPTH` (or a block that
            refers to itself), a missing block, or more than :data:`MAX_ENTITIES`.
    """
    count = [0]
    yield from _expand(layout, path, 0, None, count)


def _expand(entities, path, depth: int, layer: str | None, count: list[int]) -> Iterator:
    for e in entities:
        count[0] += 1
        if count[0] > MAX_ENTITIES:
            raise GeometryError(
                f"{path}: block references expand to more than {MAX_ENTITIES:,} entities"
            )
        if layer is not None and e.dxf.get("layer", "0") == "0":
            e.dxf.layer = layer
        if e.dxftype() != "INSERT":
            yield e
            continue
        if depth >= MAX_DEPTH:
            raise GeometryError(
                f"{path}: block references nested deeper than {MAX_DEPTH} "
                f"(block {e.dxf.name!r} refers to itself?)"
            )
        if e.block() is None:
            raise GeometryError(f"{path}: INSERT {e.dxf.handle} places a missing block")
        here = e.dxf.get("layer", "0")
        copies = e.mcount
        if copies > 1:
            if count[0] + copies > MAX_ENTITIES:
                raise GeometryError(
                    f"{path}: MINSERT {e.dxf.handle} places {copies:,} copies "
                    f"(more than {MAX_ENTITIES:,} entities)"
                )
            yield from _expand(e.multi_insert(), path, depth, here, count)
            continue
        try:
            parts = list(e.virtual_entities())
        except Exception as err:  # noqa: BLE001 - ezdxf raises many types on bad blocks
            raise GeometryError(
                f"{path}: cannot expand INSERT {e.dxf.handle} of block {e.dxf.name!r} "
                f"({one_line(err, True)})"
            ) from None
        yield from _expand(parts, path, depth + 1, here, count)
