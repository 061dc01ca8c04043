"""DXF drawings for CAD, in metres: a new drawing with named layers, the surveyed
beacons drawn on one, and the drawing written whole. ``mast track``'s ``map.dxf``
(:func:`mast.runs.outputs.write_map_dxf`) and ``mast plan``'s drawing are made with
these (ezdxf).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, Final

import numpy as np

from mast.core.beacon import Beacon
from mast.io.atomic import atomic_path

__all__ = ["DXF_TEXT_HEIGHT_M", "add_dxf_beacons", "new_dxf", "save_dxf"]

#: Height of a beacon's id in a drawing, metres.
DXF_TEXT_HEIGHT_M: Final = 0.25
#: $INSUNITS code for metres.
_DXF_METRES: Final = 6


def new_dxf(layers: Mapping[str, int]) -> tuple[Any, Any]:
    """An empty DXF R2010 drawing in metres (``$INSUNITS`` 6, ``$MEASUREMENT`` 1 metric)
    with these layers (name: ACI colour), and its modelspace."""
    from ezdxf import units
    from ezdxf.filemanagement import new

    doc = new("R2010", units=units.M)
    doc.header["$INSUNITS"] = _DXF_METRES
    doc.header["$MEASUREMENT"] = 1
    for name, colour in layers.items():
        doc.layers.add(name, color=colour)
    return doc, doc.modelspace()


def add_dxf_beacons(
    msp: Any, beacons: Iterable[Beacon], layer: str, *, text_height_m: float = DXF_TEXT_HEIGHT_M
) -> None:
    """Per beacon, an LWPOLYLINE through its four edges and a TEXT of its id at its centre."""
    from ezdxf.enums import TextEntityAlignment

    for b in beacons:
        msp.add_lwpolyline(np.asarray(b.edges).tolist(), dxfattribs={"layer": layer})
        c = b.centroid
        msp.add_text(b.id, height=text_height_m, dxfattribs={"layer": layer}).set_placement(
            (float(c[0]), float(c[1])), align=TextEntityAlignment.BOTTOM_CENTER
        )


def save_dxf(doc: Any, path: str | Path) -> None:
    """Write a drawing whole (a temporary name, renamed when complete); a failure is an
    :class:`OutputError` naming the file."""
    with atomic_path(path) as tmp:
        doc.saveas(tmp)
