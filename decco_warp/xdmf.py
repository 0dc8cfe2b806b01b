"""An XDMF sidecar for a trajectory, so that ParaView and VisIt open a run.

``trajectory.xdmf`` describes the H5MD datasets of ``trajectory.h5`` (decco_warp/io.py) and
holds no data: XDMF readers read the particles in place, each frame as a hyperslab of the
``value`` datasets.  It is a temporal collection with one grid per frame (its Time is the
frame's time [s]); each grid is the particles as points (Polyvertex topology) at their
positions [cm], with point data ``velocity`` [cm/s], ``omega`` (spin) [rad/s], ``stress``
(the particle's largest contact overlap [cm], docs/model.md), ``radius`` [cm], ``mass`` [g],
``size_class`` (0 = smallest) and ``pile_id`` (0 target, 1 projectile).

XDMF 2 syntax, which VTK's vtkXdmfReader (ParaView's "Xdmf Reader", VisIt) reads and the
XDMF 3 readers accept.  Nothing here imports Warp.
"""

from __future__ import annotations

import os
from pathlib import Path
from xml.etree import ElementTree as ET

import h5py

from .durable import write_atomic
from .folder import RunFolder
from .io import FileFormatError, Trajectory, _complete_frames, open_trajectory

#: Per-frame H5MD elements as XDMF attributes: (element, attribute name, XDMF type); position is the geometry.
FRAME_ATTRIBUTES = (("velocity", "velocity", "Vector"), ("omega", "omega", "Vector"), ("stress", "stress", "Scalar"))
#: Static H5MD datasets as XDMF attributes: (dataset, attribute name).
STATIC_ATTRIBUTES = (("radius", "radius"), ("mass", "mass"), ("species", "size_class"), ("pile_id", "pile_id"))


def write_xdmf(trajectory, xdmf=None) -> int:
    """Write the XDMF sidecar of an H5MD ``trajectory`` (default: ``trajectory.xdmf`` beside it),
    covering its complete frames (a run still being written: those written so far).  The file is
    replaced atomically, so that a viewer never reads half of it.  Returns the number of frames."""
    trajectory = Path(trajectory)
    xdmf = Path(xdmf) if xdmf is not None else trajectory.with_name(RunFolder.XDMF)
    with open_trajectory(trajectory) as f:
        particles = f["particles/all"]
        frames = min(_complete_frames(particles[name], keep_through_step=2**62) for name in Trajectory.PARTICLE_ELEMENTS)
        if frames == 0:
            raise FileFormatError(f"trajectory {trajectory} has no complete frame yet")
        times = particles["position/time"][:frames]
        source = os.path.relpath(trajectory.resolve(), xdmf.resolve().parent)
        root = _document(particles, source, times)
    _replace(xdmf, '<?xml version="1.0" ?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n' + ET.tostring(root, encoding="unicode") + "\n")
    return frames


def _document(particles: h5py.Group, source: str, times) -> ET.Element:
    n = particles["radius"].shape[0]
    root = ET.Element("Xdmf", Version="2.0")
    domain = ET.SubElement(root, "Domain")
    domain.append(ET.Comment(" decco-warp particles, cgs: stress is each particle's largest contact overlap [cm] "))
    series = ET.SubElement(domain, "Grid", Name="particles", GridType="Collection", CollectionType="Temporal")
    for k, time in enumerate(times):
        grid = ET.SubElement(series, "Grid", Name=f"frame {k}", GridType="Uniform")
        ET.SubElement(grid, "Time", Value=repr(float(time)))
        ET.SubElement(grid, "Topology", TopologyType="Polyvertex", NumberOfElements=str(n), NodesPerElement="1")
        geometry = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
        _frame_item(geometry, source, particles["position/value"], k)
        for element, name, kind in FRAME_ATTRIBUTES:
            attribute = ET.SubElement(grid, "Attribute", Name=name, AttributeType=kind, Center="Node")
            _frame_item(attribute, source, particles[f"{element}/value"], k)
        for dataset, name in STATIC_ATTRIBUTES:
            attribute = ET.SubElement(grid, "Attribute", Name=name, AttributeType="Scalar", Center="Node")
            _hdf_item(attribute, source, particles[dataset])
    ET.indent(root, space=" ")
    return root


def _hdf_item(parent: ET.Element, source: str, dataset: h5py.Dataset) -> None:
    """A DataItem that reads ``dataset`` from the HDF5 file in place."""
    kinds = {"f": "Float", "i": "Int", "u": "UInt"}
    item = ET.SubElement(
        parent, "DataItem", Format="HDF", NumberType=kinds[dataset.dtype.kind], Precision=str(dataset.dtype.itemsize),
        Dimensions=_dimensions(dataset.shape),
    )  # fmt: skip
    item.text = f"{source}:{dataset.name}"


def _frame_item(parent: ET.Element, source: str, dataset: h5py.Dataset, k: int) -> None:
    """Frame ``k`` of a (frames, N[, 3]) dataset: a hyperslab (start, stride, count per axis)."""
    frame = dataset.shape[1:]
    slab = ET.SubElement(parent, "DataItem", ItemType="HyperSlab", Type="HyperSlab", Dimensions=_dimensions(frame))
    selection = ET.SubElement(slab, "DataItem", Format="XML", Dimensions=f"3 {dataset.ndim}")
    start, stride, count = [k, *(0 for _ in frame)], [1] * dataset.ndim, [1, *frame]
    selection.text = "  ".join(" ".join(map(str, row)) for row in (start, stride, count))
    _hdf_item(slab, source, dataset)


def _dimensions(shape) -> str:
    return " ".join(str(int(d)) for d in shape)


def _replace(path: Path, text: str) -> None:
    write_atomic(path, text)  # a full disk leaves the previous file, and no temporary, behind
