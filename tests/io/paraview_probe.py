"""What a VTK reader made of an XDMF file: its time steps and, at the last one, every block's
name, point count and arrays, as JSON. Run by ParaView's pvbatch for ParaView's readers,

    pvbatch paraview_probe.py READER FILE.xmf

and imported by the tests for VTK's own reader (`describe`).
"""

import json
import sys


def _arrays(attributes) -> dict:
    out = {}
    for i in range(attributes.GetNumberOfArrays()):
        array = attributes.GetArray(i)
        out[array.GetName()] = [array.GetTuple(j) for j in range(array.GetNumberOfTuples())]
    return out


def _leaves(node, name):
    if node.IsA("vtkCompositeDataSet"):  # a multiblock, or a multipiece of partitions
        pieces = node.IsA("vtkPartitionedDataSet")
        for i in range(node.GetNumberOfPartitions() if pieces else node.GetNumberOfBlocks()):
            meta = node.GetMetaData(i)
            child = meta.Get(node.NAME()) if meta.Has(node.NAME()) else None
            yield from _leaves(node.GetPartitionAsDataObject(i) if pieces else node.GetBlock(i), child)
    else:
        points = node.GetPoints() if node.IsA("vtkPointSet") else None
        yield {
            "name": name,
            "class": node.GetClassName(),
            "points": node.GetNumberOfPoints(),
            "cells": node.GetNumberOfCells(),
            "coordinates": [points.GetPoint(j) for j in range(points.GetNumberOfPoints())]
            if points
            else None,
            "point_arrays": _arrays(node.GetPointData()),
            "cell_arrays": _arrays(node.GetCellData()),
        }


def describe(times: list[float], data) -> dict:
    return {"times": [float(t) for t in times], "blocks": list(_leaves(data, None))}


if __name__ == "__main__":
    from paraview import servermanager, simple

    reader = getattr(simple, sys.argv[1])(FileName=[sys.argv[2]])
    reader.UpdatePipelineInformation()
    steps = list(reader.TimestepValues)
    reader.UpdatePipeline(steps[-1])
    print(json.dumps(describe(steps, servermanager.Fetch(reader))))
