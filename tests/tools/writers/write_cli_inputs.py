#!/usr/bin/python3
"""Writes one small u16 volume in every format `brickcast ingest` dispatches on (FormatsCliTest).

    write_cli_inputs.py FOLDER

FOLDER gets vol.raw (40x30x20 u16, x fastest: the source), scan.h5 (the volume at /a/vol, a 2D
dataset at /b/flat), ome.zarr (OME-Zarr, two levels: level 1 strided by 2), slices/ (one TIFF
per z-slice, unpadded names), vol.mha and vol.vti (VTK's writers).
"""
import os
import sys

import numpy as np

out = sys.argv[1]
z, y, x = 20, 30, 40
k, j, i = np.meshgrid(np.arange(z), np.arange(y), np.arange(x), indexing="ij")
vol = ((i * 7 + j * 131 + k * 1009) % 60000).astype(np.uint16)
vol.tofile(os.path.join(out, "vol.raw"))

import h5py  # noqa: E402

with h5py.File(os.path.join(out, "scan.h5"), "w") as f:
    f.create_dataset("/a/vol", data=vol, chunks=(8, 16, 16), compression="gzip")
    f.create_dataset("/b/flat", data=vol[0])

import zarr  # noqa: E402

root = zarr.open_group(os.path.join(out, "ome.zarr"), mode="w")
root.create_dataset("0", data=vol, chunks=(8, 16, 16))
root.create_dataset("1", data=vol[::2, ::2, ::2], chunks=(8, 16, 16))
root.attrs["multiscales"] = [{
    "version": "0.4",
    "axes": [{"name": "z", "type": "space", "unit": "micrometer"},
             {"name": "y", "type": "space", "unit": "micrometer"},
             {"name": "x", "type": "space", "unit": "micrometer"}],
    "datasets": [
        {"path": "0", "coordinateTransformations": [{"type": "scale", "scale": [2.0, 1.0, 1.0]}]},
        {"path": "1", "coordinateTransformations": [{"type": "scale", "scale": [4.0, 2.0, 2.0]}]},
    ],
}]

import tifffile  # noqa: E402

os.makedirs(os.path.join(out, "slices"))
for n in range(z):
    tifffile.imwrite(os.path.join(out, "slices", f"s{n}.tif"), vol[n], photometric="minisblack")

import vtk  # noqa: E402
from vtk.util import numpy_support  # noqa: E402

image = vtk.vtkImageData()
image.SetDimensions(x, y, z)
image.SetSpacing(1.0, 1.0, 1.0)
array = numpy_support.numpy_to_vtk(vol.ravel(), deep=True, array_type=vtk.VTK_UNSIGNED_SHORT)
array.SetName("density")
image.GetPointData().SetScalars(array)
mha = vtk.vtkMetaImageWriter()
mha.SetFileName(os.path.join(out, "vol.mha"))
mha.SetCompression(True)
mha.SetInputData(image)
mha.Write()
vti = vtk.vtkXMLImageDataWriter()
vti.SetFileName(os.path.join(out, "vol.vti"))
vti.SetInputData(image)
vti.Write()
