"""XDMF 3 sidecar so ParaView opens the particles of trajectory.h5 without copying data.

One grid per frame: a Polyvertex topology over the N particles, the position hyperslab of that
frame as geometry, radius (cell-independent, written once) and each vector field as node
attributes. Rewritten atomically after each frame.
"""

from __future__ import annotations

from pathlib import Path

from .atomic import write_text_atomic

VECTOR_NAMES = {
    "velocity": "velocity",
    "angular_velocity": "angular_velocity",
    "force": "force",
    "torque": "torque",
}


def _slab(h5name: str, dataset: str, frame: int, frames: int, n: int) -> str:
    return (
        f'<DataItem ItemType="HyperSlab" Dimensions="{n} 3" Type="HyperSlab">'
        f'<DataItem Dimensions="3 3" Format="XML">{frame} 0 0 1 1 1 1 {n} 3</DataItem>'
        f'<DataItem Dimensions="{frames} {n} 3" NumberType="Float" Precision="8" Format="HDF">'
        f"{h5name}:{dataset}</DataItem></DataItem>"
    )


def write_xdmf(path: Path, h5name: str, times, n: int, fields: list[str]) -> None:
    frames = len(times)
    grids = []
    for k, t in enumerate(times):
        attrs = [
            f'<Attribute Name="radius" AttributeType="Scalar" Center="Node">'
            f'<DataItem Dimensions="{n}" NumberType="Float" Precision="8" Format="HDF">'
            f"{h5name}:/particles/trajectory/radius</DataItem></Attribute>"
        ]
        for field in fields:
            attrs.append(
                f'<Attribute Name="{VECTOR_NAMES[field]}" AttributeType="Vector" Center="Node">'
                + _slab(h5name, f"/particles/trajectory/{field}/value", k, frames, n)
                + "</Attribute>"
            )
        grids.append(
            f'<Grid Name="frame{k}" GridType="Uniform"><Time Value="{t!r}"/>'
            f'<Topology TopologyType="Polyvertex" NumberOfElements="{n}"/>'
            f'<Geometry GeometryType="XYZ">'
            + _slab(h5name, "/particles/trajectory/position/value", k, frames, n)
            + "</Geometry>"
            + "".join(attrs)
            + "</Grid>"
        )
    text = (
        '<?xml version="1.0" ?>\n<Xdmf Version="3.0"><Domain>'
        '<Grid Name="particles" GridType="Collection" CollectionType="Temporal">\n'
        + "\n".join(grids)
        + "\n</Grid></Domain></Xdmf>\n"
    )
    write_text_atomic(path, text)
