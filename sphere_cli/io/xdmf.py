"""XDMF 3 sidecar so ParaView opens the particles of trajectory.h5 without copying data.

One grid per frame: a Polyvertex topology over the N particles, the position hyperslab of that
frame as geometry, radius (cell-independent, written once) and each vector field as node
attributes. With a fluid on a 3D grid, each frame is a spatial collection of the particles and
a 3DCoRectMesh whose cell attributes are the fluid fields (stored z-major, see trajectory.py),
with the grid spacing of that frame when the grid moves (one that follows the top wall).
Rewritten atomically after each frame.
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


def _grid_slab(h5name: str, name: str, frame: int, frames: int, cells: tuple, components: int) -> str:
    nz, ny, nx = cells
    inner = f"{nz} {ny} {nx}" + (f" {components}" if components > 1 else "")
    rank = 4 if components > 1 else 3
    start = " ".join(["0"] * rank)
    stride = " ".join(["1"] * (rank + 1))
    count = f"1 {inner}"
    return (
        f'<DataItem ItemType="HyperSlab" Dimensions="{inner}" Type="HyperSlab">'
        f'<DataItem Dimensions="3 {rank + 1}" Format="XML">{frame} {start} {stride} {count}</DataItem>'
        f'<DataItem Dimensions="{frames} {inner}" NumberType="Float" Precision="8" Format="HDF">'
        f"{h5name}:/fluid/{name}/value</DataItem></DataItem>"
    )


def _xml_vector(*values: float) -> str:
    text = " ".join(repr(v) for v in values)
    item = f'<DataItem Dimensions="{len(values)}" NumberType="Float" Precision="8" Format="XML">'
    return f"{item}{text}</DataItem>"


def _fluid_grid(h5name: str, k: int, frames: int, grid, fields: dict, spacing=None) -> str:
    """`spacing`: None for a fixed grid, else (frames, 3) [m] the spacing of each frame."""
    nx, ny, nz = (int(c) for c in grid.shape)
    ox, oy, oz = (float(c) for c in grid.origin)
    dx, dy, dz = (float(c) for c in (grid.spacing if spacing is None else spacing[k]))
    attrs = "".join(
        f'<Attribute Name="{name}" AttributeType="{"Vector" if comps == 3 else "Scalar"}" Center="Cell">'
        + _grid_slab(h5name, name, k, frames, (nz, ny, nx), comps)
        + "</Attribute>"
        for name, comps in fields.items()
    )
    return (
        f'<Grid Name="fluid{k}" GridType="Uniform">'
        f'<Topology TopologyType="3DCoRectMesh" Dimensions="{nz + 1} {ny + 1} {nx + 1}"/>'
        f'<Geometry GeometryType="ORIGIN_DXDYDZ">'
        f"{_xml_vector(oz, oy, ox)}{_xml_vector(dz, dy, dx)}"
        f"</Geometry>{attrs}</Grid>"
    )


def write_xdmf(path: Path, h5name: str, times, n: int, fields: list[str], fluid=None) -> None:
    """`fluid`: None, or (FluidGrid, {field name: components}, spacing) for the 3D fluid fields,
    spacing None for a fixed grid or (frames, 3) [m] per frame for a moving one."""
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
        particles = (
            f'<Grid Name="{"particles" if fluid else "frame"}{k}" GridType="Uniform"><Time Value="{t!r}"/>'
            f'<Topology TopologyType="Polyvertex" NumberOfElements="{n}"/>'
            f'<Geometry GeometryType="XYZ">'
            + _slab(h5name, "/particles/trajectory/position/value", k, frames, n)
            + "</Geometry>"
            + "".join(attrs)
            + "</Grid>"
        )
        if fluid is None:
            grids.append(particles)
        else:
            grids.append(
                f'<Grid Name="frame{k}" GridType="Collection" CollectionType="Spatial"><Time Value="{t!r}"/>'
                + particles
                + _fluid_grid(h5name, k, frames, *fluid)
                + "</Grid>"
            )
    text = (
        '<?xml version="1.0" ?>\n<Xdmf Version="3.0"><Domain>'
        '<Grid Name="particles" GridType="Collection" CollectionType="Temporal">\n'
        + "\n".join(grids)
        + "\n</Grid></Domain></Xdmf>\n"
    )
    write_text_atomic(path, text)
