"""VTK's CPU volume ray caster (``vtkFixedPointVolumeRayCastMapper``): the peer of ``bench
volume``, drawn off screen in an EGL window.

Needs ``vtk`` (the ``peers`` extra; a wheel with ``vtkEGLRenderWindow``) and Mesa's EGL
(``scripts/setup_peers.sh``); :func:`raycast_time` raises
:class:`~mi_displace.bench.peers.PeerUnavailable` without them.
"""
from __future__ import annotations

import statistics
import time

import numpy as np

from mi_displace.bench.peers import PeerUnavailable, require


def raycast_time(obj, eye, target, fov_deg: float, size: int, iso: float, threads: int = 2,
                 frames: int = 3) -> float:
    """Warm median seconds of ``frames`` renders (after a cold one) of ``obj`` at ``size`` x
    ``size`` pixels: fixed-point ray casting, sample distance one voxel, automatic
    adjustment off, linear interpolation, shading on, an opacity step of width 0.06 at
    ``iso`` (of the [0, 1] values), ``threads`` threads.

    Args:
        obj: :class:`mi_displace.volume.objects.ObjectVolume` (data (Z, Y, X) in [0, 1],
            ``voxel_size`` and ``bbox_min`` in world units).
        eye, target: camera position and look-at point (world units); z is up.
        fov_deg: vertical view angle (degrees).
    """
    vtk = require("vtk")
    numpy_support = require("vtk.util.numpy_support")
    if not hasattr(vtk, "vtkEGLRenderWindow"):
        raise PeerUnavailable(f"this vtk {vtk.vtkVersion.GetVTKVersion()} has no EGL window")
    n = obj.shape
    data = np.ascontiguousarray(np.clip(obj.data * 255, 0, 255).astype(np.uint8))
    image = vtk.vtkImageData()
    image.SetDimensions(n[2], n[1], n[0])
    h = obj.voxel_size
    image.SetSpacing(*h)
    image.SetOrigin(*(obj.bbox_min + 0.5 * h))
    image.GetPointData().SetScalars(numpy_support.numpy_to_vtk(data.ravel(), deep=True,
                                                               array_type=vtk.VTK_UNSIGNED_CHAR))
    mapper = vtk.vtkFixedPointVolumeRayCastMapper()
    mapper.SetInputData(image)
    mapper.SetAutoAdjustSampleDistances(0)
    mapper.SetSampleDistance(1.0 * float(h.min()))  # one voxel, in world units
    mapper.SetNumberOfThreads(threads)
    opacity = vtk.vtkPiecewiseFunction()
    opacity.AddPoint(0, 0.0)
    opacity.AddPoint(255 * (iso - 0.03), 0.0)
    opacity.AddPoint(255 * (iso + 0.03), 1.0)
    opacity.AddPoint(255, 1.0)
    color = vtk.vtkColorTransferFunction()
    color.AddRGBPoint(0, 0.8, 0.7, 0.55)
    color.AddRGBPoint(255, 0.8, 0.7, 0.55)
    prop = vtk.vtkVolumeProperty()
    prop.SetScalarOpacity(opacity)
    prop.SetColor(color)
    prop.ShadeOn()
    prop.SetInterpolationTypeToLinear()
    volume = vtk.vtkVolume()
    volume.SetMapper(mapper)
    volume.SetProperty(prop)
    renderer = vtk.vtkRenderer()
    renderer.AddVolume(volume)
    camera = renderer.GetActiveCamera()
    camera.SetPosition(*eye)
    camera.SetFocalPoint(*target)
    camera.SetViewUp(0, 0, 1)
    camera.SetViewAngle(fov_deg)
    window = vtk.vtkEGLRenderWindow()
    window.SetOffScreenRendering(1)
    window.AddRenderer(renderer)
    window.SetSize(size, size)
    times = []
    for _ in range(frames + 1):
        start = time.perf_counter()
        window.Render()
        times.append(time.perf_counter() - start)
    return statistics.median(times[1:])
