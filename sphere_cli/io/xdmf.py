"""XDMF 3 sidecar so ParaView opens trajectory.h5 without copying data.

A temporal collection with one grid per frame: a Polyvertex topology over the N particles, the
frame's positions as geometry, radius (time-independent) and each vector field as node
attributes. With a fluid on a 3D grid, a second temporal collection beside it holds a
3DCoRectMesh per frame whose cell attributes are the fluid fields (stored z-major, see
trajectory.py), with the grid spacing of that frame when the grid moves (one that follows the top
wall).

Each frame's arrays are the per-frame virtual datasets of trajectory.py (VIEWS), referenced as
plain HDF datasets: both ParaView's XDMF 3 readers and the legacy XDMF reader (VTK's
vtkXdmfReader) read those, where the XDMF 3 readers read no hyperslab of a time series. Block
names are the same in every frame ("particles", "fluid"), so a selection made at one frame holds
at all. The file is replaced atomically after each frame; the text of the frames before is kept
in memory, so only the new frame is formatted.
"""

from __future__ import annotations

from pathlib import Path

from .atomic import write_text_atomic
from .trajectory import GROUP, VERTICES, xdmf_view


def _hdf(h5name: str, dataset: str, dims: tuple) -> str:
    return (
        f'<DataItem Dimensions="{" ".join(map(str, dims))}" NumberType="Float" Precision="8" '
        f'Format="HDF">{h5name}:{dataset}</DataItem>'
    )


def _xml_vector(*values: float) -> str:
    text = " ".join(repr(float(v)) for v in values)
    item = f'<DataItem Dimensions="{len(values)}" NumberType="Float" Precision="8" Format="XML">'
    return f"{item}{text}</DataItem>"


def _fluid_grid(h5name: str, k: int, time: float, grid, fields: dict, spacing) -> str:
    """`spacing`: (3,) [m] the cell edges of this frame."""
    nx, ny, nz = (int(c) for c in grid.shape)
    ox, oy, oz = (float(c) for c in grid.origin)
    dx, dy, dz = (float(c) for c in spacing)
    attrs = "".join(
        f'<Attribute Name="{name}" AttributeType="{"Vector" if comps == 3 else "Scalar"}" Center="Cell">'
        + _hdf(h5name, xdmf_view(f"/fluid/{name}", k), (nz, ny, nx) + ((comps,) if comps > 1 else ()))
        + "</Attribute>"
        for name, comps in fields.items()
    )
    return (
        f'<Grid Name="fluid" GridType="Uniform"><Time Value="{time!r}"/>'
        f'<Topology TopologyType="3DCoRectMesh" Dimensions="{nz + 1} {ny + 1} {nx + 1}"/>'
        f'<Geometry GeometryType="ORIGIN_DXDYDZ">'
        f"{_xml_vector(oz, oy, ox)}{_xml_vector(dz, dy, dx)}"
        f"</Geometry>{attrs}</Grid>"
    )


def frame_grid(h5name: str, k: int, time: float, n: int, fields: list[str], fluid=None) -> str:
    """The grids of frame `k` at `time` [s]: the particles' (none, "", when n = 0: a fluid-only
    scene) and, with `fluid` = (FluidGrid, {field name: components}, spacing (3,) [m] of this
    frame), the 3D fluid fields' (else "")."""
    fluid_grid = "" if fluid is None else _fluid_grid(h5name, k, float(time), *fluid)
    if n == 0:
        return "", fluid_grid
    attrs = [
        '<Attribute Name="radius" AttributeType="Scalar" Center="Node">'
        + _hdf(h5name, f"{GROUP}/radius", (n,))
        + "</Attribute>"
    ]
    for field in fields:
        attrs.append(
            f'<Attribute Name="{field}" AttributeType="Vector" Center="Node">'
            + _hdf(h5name, xdmf_view(f"{GROUP}/{field}", k), (n, 3))
            + "</Attribute>"
        )
    particles = (
        f'<Grid Name="particles" GridType="Uniform"><Time Value="{float(time)!r}"/>'
        f'<Topology TopologyType="Polyvertex" NumberOfElements="{n}" NodesPerElement="1">'
        f'<DataItem Dimensions="{n}" NumberType="Int" Precision="8" Format="HDF">'
        f"{h5name}:{VERTICES}</DataItem>"
        "</Topology>"
        '<Geometry GeometryType="XYZ">'
        + _hdf(h5name, xdmf_view(f"{GROUP}/position", k), (n, 3))
        + "</Geometry>"
        + "".join(attrs)
        + "</Grid>"
    )
    return particles, fluid_grid


def write_xdmf(path: Path, grids: list[tuple[str, str]]) -> None:
    """The sidecar of the frames whose (particle, fluid) grids (frame_grid) are given, replaced
    atomically: a temporal collection of the particles (with particles) and, with a fluid on a
    3D grid, one of the fluid cells beside it (in one collection of both per frame, the readers
    would rename the blocks of every frame but the first)."""
    collections = []
    if grids and grids[0][0]:
        collections.append(("particles", [p for p, _ in grids]))
    if grids and grids[0][1]:
        collections.append(("fluid", [fl for _, fl in grids]))
    text = '<?xml version="1.0" ?>\n<Xdmf Version="3.0"><Domain>\n'
    for name, frames in collections:
        text += f'<Grid Name="{name}" GridType="Collection" CollectionType="Temporal">\n'
        text += "\n".join(frames) + "\n</Grid>\n"
    write_text_atomic(path, text + "</Domain></Xdmf>\n")
