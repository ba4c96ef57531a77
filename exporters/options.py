"""Options shared by the mask exporters."""

from __future__ import annotations

from dataclasses import dataclass

from optdot.errors import ExportError
from optdot.geometry.kinds import Kind
from optdot.printing.laser import Laser
from optdot.printing.process import Process
from optdot.printing.sheet import Sheet

DXF_VERSIONS = ("R12", "R2000", "R2004", "R2007", "R2010", "R2013", "R2018")


@dataclass(frozen=True)
class ExportOptions:
    """How masks are written.

    Attributes:
        tolerance_um: max distance between the true circle and its polygon, µm (GDS/OAS).
        flatten: write one polygon per dot instead of one dot cell + references.
        layer, datatype: GDS/OAS layer of the dots.
        outline_layer, outline_datatype: GDS/OAS layer of the panel outline.
        top_cell: name of the top cell.
        dot_cell: name of the dot cell.
        dxf_version: DXF release (R2010 default; R12 for older CAM).
        speos_reference_mm: the diameter a Speos texture element stands for, mm (scale
            1); None: the pattern's nominal diameter.
        provenance: ``"key: value"`` lines a mask carries where its format has a place
            for them (GDSII/OASIS: properties 1, 2, ... of the outline's first polygon;
            DXF R2000+: custom header properties), each at most 126 bytes.
        process: how the mask prints (the job's ``[process]``), or None: a mask draws
            the pattern's footprints as they are. With one, a mask draws each footprint
            shrunk by the dot gain, scaled for the shrink, mirrored and on the grid
            (:mod:`optdot.printing.mask`), and a mask read back is the print it makes.
        laser: the laser dotting machine a laser path is written for (the job's
            ``[laser]``: its sizes, speed, acceleration, dwell), or None.
        sheet: the production sheet a mask repeats the panel on (the job's ``[sheet]``),
            or None: the mask is one panel.
        kind: the job's dot kind: a mask's dots are recognised as it where it is made
            per job (a polygon, whose vertices only the job knows), or None.
        labels: each panel's label on the sheet, row by row
            (:func:`optdot.printing.sheet.label_text`).
        fixed_depth: the job's 3-D dots stand (or sink) the same height whatever their
            size (``[dots] profile = "bump"`` or ``"dimple"``): a Speos mapping scales its
            elements' z by 1, not by their diameter.
    """

    tolerance_um: float = 0.01
    flatten: bool = False
    layer: int = 1
    datatype: int = 0
    outline_layer: int = 2
    outline_datatype: int = 0
    top_cell: str = "TOP"
    dot_cell: str = "DOT"
    dxf_version: str = "R2010"
    speos_reference_mm: float | None = None
    provenance: tuple[str, ...] = ()
    process: Process | None = None
    laser: Laser | None = None
    sheet: Sheet | None = None
    kind: Kind | None = None
    labels: tuple[str, ...] = ()
    fixed_depth: bool = False

    def __post_init__(self) -> None:
        if not 1e-4 <= self.tolerance_um <= 10:
            raise ExportError(f"--tolerance {self.tolerance_um} µm is out of range (0.0001..10)")
        for name in ("layer", "datatype", "outline_layer", "outline_datatype"):
            v = getattr(self, name)
            if not 0 <= v <= 65535:
                raise ExportError(f"--{name.replace('_', '-')} {v} is out of range (0..65535)")
        for name in ("top_cell", "dot_cell"):
            v = getattr(self, name)
            if not v or not v.isascii() or not all(c.isalnum() or c in "_-$?" for c in v):
                raise ExportError(f"--{name.replace('_', '-')} {v!r}: use letters, digits, _ - $ ?")
        if (self.layer, self.datatype) == (self.outline_layer, self.outline_datatype):
            raise ExportError(
                f"--layer {self.layer}/{self.datatype} is also the outline's layer "
                "(--outline-layer): dots and outline need different layers"
            )
        if self.top_cell == self.dot_cell:
            raise ExportError("--top-cell and the dot cell must differ")
        ref = self.speos_reference_mm
        if ref is not None and not (0 < ref < float("inf")):
            raise ExportError(f"--speos-reference-diameter {ref} must be > 0 mm")
        for line in self.provenance:
            if ": " not in line or len(line.encode()) > 126:
                raise ExportError(f"provenance line {line[:40]!r}...: 'key: value', 126 bytes")
        if self.dxf_version not in DXF_VERSIONS:
            raise ExportError(f"--dxf-version {self.dxf_version!r}: use one of {DXF_VERSIONS}")
