"""Render one frame of a run through its trajectory.xdmf, as ParaView would read it (docs/running.md: "Opening a
run in ParaView or VisIt"): VTK's XDMF reader, spheres of the particles' radii coloured by stress (largest
overlap), drawn offscreen.  Needs `pip install vtk`.

    python docs/figures/xdmf_example.py runs/out/default/trajectory.xdmf --time 400 --stress-max 2e4 --out docs/figures/xdmf-example.png
"""

import argparse

import numpy as np
import vtkmodules.vtkRenderingFreeType  # noqa: F401  (text)
import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (offscreen: EGL or OSMesa without a display)
from matplotlib import colormaps
from vtkmodules.vtkCommonCore import vtkLookupTable
from vtkmodules.vtkCommonDataModel import vtkDataObject
from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline
from vtkmodules.vtkFiltersCore import vtkGlyph3D
from vtkmodules.vtkFiltersSources import vtkSphereSource
from vtkmodules.vtkIOImage import vtkPNGWriter
from vtkmodules.vtkIOXdmf2 import vtkXdmfReader
from vtkmodules.vtkRenderingAnnotation import vtkScalarBarActor
from vtkmodules.vtkRenderingCore import vtkActor, vtkPolyDataMapper, vtkRenderer, vtkRenderWindow, vtkTextActor, vtkWindowToImageFilter


def viridis(top: float | None = None) -> vtkLookupTable:
    table = vtkLookupTable()
    table.SetNumberOfTableValues(256)
    for k, rgba in enumerate(colormaps["viridis"](np.linspace(0.0, 1.0, 256))):
        table.SetTableValue(k, *rgba)
    if top is not None:
        table.SetTableRange(0.0, top)
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("xdmf")
    parser.add_argument("--time", type=float, default=None, help="simulated time [s] (the nearest frame; default: the last)")
    parser.add_argument("--out", default="xdmf-example.png")
    parser.add_argument("--stress-max", type=float, default=1e5, help="top of the colour scale [cm]")
    args = parser.parse_args()

    reader = vtkXdmfReader()
    reader.SetFileName(args.xdmf)
    reader.UpdateInformation()
    times = np.array(reader.GetOutputInformation(0).Get(vtkStreamingDemandDrivenPipeline.TIME_STEPS()))
    time = times[-1] if args.time is None else times[np.argmin(np.abs(times - args.time))]
    reader.UpdateTimeStep(time)

    sphere = vtkSphereSource()  # radius 1, scaled by each particle's radius [cm]
    sphere.SetRadius(1.0)
    sphere.SetThetaResolution(20)
    sphere.SetPhiResolution(14)
    glyphs = vtkGlyph3D()
    glyphs.SetInputConnection(reader.GetOutputPort())
    glyphs.SetSourceConnection(sphere.GetOutputPort())
    glyphs.SetInputArrayToProcess(0, 0, 0, vtkDataObject.FIELD_ASSOCIATION_POINTS, "radius")
    glyphs.SetInputArrayToProcess(3, 0, 0, vtkDataObject.FIELD_ASSOCIATION_POINTS, "stress")
    glyphs.SetScaleModeToScaleByScalar()
    glyphs.SetColorModeToColorByScalar()

    mapper = vtkPolyDataMapper()
    mapper.SetInputConnection(glyphs.GetOutputPort())
    mapper.SetLookupTable(viridis())
    mapper.SetScalarRange(0.0, args.stress_max)
    actor = vtkActor()
    actor.SetMapper(mapper)

    bar = vtkScalarBarActor()
    bar.SetLookupTable(viridis(args.stress_max / 1e5))  # the same colours, labelled in km
    bar.SetTitle("stress: largest overlap (km)")
    bar.SetNumberOfLabels(3)
    bar.SetLabelFormat("%.2f")
    bar.SetOrientationToHorizontal()
    bar.SetPosition(0.25, 0.02)
    bar.SetWidth(0.5)
    bar.SetHeight(0.12)
    label = vtkTextActor()
    label.SetInput(f"t = {time:.0f} s")
    label.SetPosition(12, 12)
    for text in (bar.GetTitleTextProperty(), bar.GetLabelTextProperty(), label.GetTextProperty()):
        text.SetColor(0.1, 0.1, 0.1)
        text.SetFontSize(16)
        text.ShadowOff()
        text.ItalicOff()

    renderer = vtkRenderer()
    renderer.SetBackground(1.0, 1.0, 1.0)
    for item in (actor, bar, label):
        renderer.AddActor(item)
    renderer.ResetCamera()  # looking down -z onto the collision plane
    renderer.GetActiveCamera().Zoom(1.3)
    window = vtkRenderWindow()
    window.SetOffScreenRendering(1)
    window.SetSize(640, 420)
    window.AddRenderer(renderer)
    window.Render()
    image = vtkWindowToImageFilter()
    image.SetInput(window)
    writer = vtkPNGWriter()
    writer.SetFileName(args.out)
    writer.SetInputConnection(image.GetOutputPort())
    writer.Write()
    print(f"wrote {args.out}: frame at t = {time:g} s")


if __name__ == "__main__":
    main()
