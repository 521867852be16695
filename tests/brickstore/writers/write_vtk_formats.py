"""Writes a raw volume as MetaImage and VTK XML image data with VTK's own writers, the
independent side of the MetaImage and .vti readers' round trips (tests/brickstore/
MetaImageReaderTest.cpp, VtiReaderTest.cpp).

usage: write_vtk_formats.py RAW DTYPE X Y Z SX SY SZ OUTDIR VARIANT...

RAW holds X*Y*Z voxels of the NumPy DTYPE, x fastest, little endian; SX SY SZ is the spacing.
Each VARIANT writes OUTDIR/VARIANT.mha, .mhd or .vti:
  mha, mha-zlib, mhd, mhd-zlib                vtkMetaImageWriter (an .mhd beside its .raw/.zraw)
  vti-{raw,b64,inline}[-zlib][-u64][-be][-blkN] vtkXMLImageDataWriter: appended raw
      (EncodeAppendedDataOff), appended base64, inline binary; the zlib compressor; UInt64
      block headers; big-endian bytes;
      compressor blocks of N bytes
"""
import sys

import numpy as np
from vtkmodules.util import numpy_support
from vtkmodules.vtkCommonDataModel import vtkImageData
from vtkmodules.vtkIOImage import vtkMetaImageWriter
from vtkmodules.vtkIOXML import vtkXMLImageDataWriter


def image(raw, dtype, dims, spacing):
    # vtkImageData's x is fastest: NumPy's C order of a (z, y, x) array.
    voxels = np.fromfile(raw, dtype=np.dtype(dtype).newbyteorder("<"))
    voxels = voxels.reshape(dims[2], dims[1], dims[0]).astype(np.dtype(dtype))
    img = vtkImageData()
    img.SetDimensions(*dims)
    img.SetSpacing(*spacing)
    img.SetOrigin(-1.5, 2.0, 10.25)
    scalars = numpy_support.numpy_to_vtk(voxels.ravel(), deep=True)
    scalars.SetName("density")
    img.GetPointData().SetScalars(scalars)
    return img


def write_meta(img, outdir, variant):
    writer = vtkMetaImageWriter()
    writer.SetInputData(img)
    writer.SetFileName(f"{outdir}/{variant}.{variant[:3]}")
    writer.SetCompression(variant.endswith("-zlib"))
    writer.Write()


def write_vti(img, outdir, variant):
    parts = variant.split("-")
    writer = vtkXMLImageDataWriter()
    writer.SetInputData(img)
    writer.SetFileName(f"{outdir}/{variant}.vti")
    if parts[1] == "inline":
        writer.SetDataModeToBinary()
    else:
        writer.SetDataModeToAppended()
        writer.SetEncodeAppendedData(parts[1] == "b64")
    if "zlib" in parts:
        writer.SetCompressorTypeToZLib()
    else:
        writer.SetCompressorTypeToNone()
    if "u64" in parts:
        writer.SetHeaderTypeToUInt64()
    else:
        writer.SetHeaderTypeToUInt32()
    if "be" in parts:
        writer.SetByteOrderToBigEndian()
    else:
        writer.SetByteOrderToLittleEndian()
    for p in parts:
        if p.startswith("blk"):
            writer.SetBlockSize(int(p[3:]))
    if writer.Write() != 1:
        sys.exit(f"vtkXMLImageDataWriter failed on {variant}")


def main():
    raw, dtype = sys.argv[1], sys.argv[2]
    dims = [int(v) for v in sys.argv[3:6]]
    spacing = [float(v) for v in sys.argv[6:9]]
    outdir = sys.argv[9]
    img = image(raw, dtype, dims, spacing)
    for variant in sys.argv[10:]:
        if variant.startswith("vti-"):
            write_vti(img, outdir, variant)
        elif variant in ("mha", "mha-zlib", "mhd", "mhd-zlib"):
            write_meta(img, outdir, variant)
        else:
            sys.exit(f"unknown variant {variant}")


if __name__ == "__main__":
    main()
