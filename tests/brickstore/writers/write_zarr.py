"""Writes a raw volume as Zarr v2 arrays and OME-Zarr images with python3-zarr, the
independent writer of the Zarr reader's round trips (tests/brickstore/ZarrReaderTest.cpp).

Usage: write_zarr.py RAW X,Y,Z DTYPE OUTDIR VARIANT...
  RAW      little-endian voxels, x fastest (test::dumpRaw)
  DTYPE    NumPy dtype name: uint8, uint16, int16, float32
  VARIANT  NAME:KIND:COMPRESSOR:SEP:CZ,CY,CX:ENDIAN[:FILL[:SPARSE]]
           KIND      array (OUTDIR/NAME is a Zarr array) or ome (OUTDIR/NAME is an OME-Zarr
                     image: level 0 the volume, level 1 the volume strided [::2, ::2, ::2], 5D
                     axes t, c, z, y, x in micrometers; OUTDIR/NAME.level1.raw holds level 1)
           COMPRESSOR none, zlib, gzip, zstd, or blosc-CNAME-SHUFFLE (CNAME lz4, zstd, blosclz;
                     SHUFFLE noshuffle, shuffle, bitshuffle)
           SEP       . or / (the chunk keys' dimension_separator)
           ENDIAN    < or >
           FILL      the fill_value (default 0)
           SPARSE    "sparse": chunks holding only the fill value are not written
"""
import sys

import numcodecs
import numpy as np
import zarr

# Voxel size of the OME-Zarr images' level 0 along z, y, x in micrometers (the reader's test
# expects these in millimetres, and twice them at level 1).
OME_SCALE_UM = [2.0, 0.5, 0.25]

SHUFFLES = {
    "noshuffle": numcodecs.Blosc.NOSHUFFLE,
    "shuffle": numcodecs.Blosc.SHUFFLE,
    "bitshuffle": numcodecs.Blosc.BITSHUFFLE,
}


def compressor(name):
    if name == "none":
        return None
    if name == "zlib":
        return numcodecs.Zlib(level=1)
    if name == "gzip":
        return numcodecs.GZip(level=1)
    if name == "zstd":
        return numcodecs.Zstd(level=1)
    kind, cname, shuffle = name.split("-")
    assert kind == "blosc", name
    return numcodecs.Blosc(cname=cname, clevel=5, shuffle=SHUFFLES[shuffle])


def write_array(path, data, chunks, options):
    array = zarr.open_array(
        path,
        mode="w",
        shape=data.shape,
        chunks=chunks,
        dtype=data.dtype,
        order="C",
        **options,
    )
    array[...] = data


def write_ome(path, name, volume, chunks, options):
    root = zarr.open_group(path, mode="w")
    levels = [volume, np.ascontiguousarray(volume[::2, ::2, ::2])]
    datasets = []
    for level, data in enumerate(levels):
        root.create_dataset(
            str(level),
            data=data[np.newaxis, np.newaxis],
            chunks=(1, 1) + tuple(chunks),
            order="C",
            **options,
        )
        scale = [1.0, 1.0] + [s * 2**level for s in OME_SCALE_UM]
        datasets.append(
            {
                "path": str(level),
                "coordinateTransformations": [{"type": "scale", "scale": scale}],
            }
        )
    root.attrs["multiscales"] = [
        {
            "version": "0.4",
            "name": name,
            "axes": [
                {"name": "t", "type": "time", "unit": "second"},
                {"name": "c", "type": "channel"},
                {"name": "z", "type": "space", "unit": "micrometer"},
                {"name": "y", "type": "space", "unit": "micrometer"},
                {"name": "x", "type": "space", "unit": "micrometer"},
            ],
            "datasets": datasets,
        }
    ]
    return levels[1]


def main(raw, dims, dtype, outdir, variants):
    x, y, z = (int(d) for d in dims.split(","))
    volume = np.fromfile(raw, dtype=np.dtype(dtype).newbyteorder("<")).reshape(z, y, x)
    for variant in variants:
        fields = variant.split(":")
        name, kind, codec, sep, chunk_text, endian = fields[:6]
        fill = fields[6] if len(fields) > 6 else "0"
        sparse = len(fields) > 7 and fields[7] == "sparse"
        data = volume.astype(np.dtype(dtype).newbyteorder(endian))
        chunks = tuple(int(c) for c in chunk_text.split(","))
        options = {
            "compressor": compressor(codec),
            "fill_value": np.dtype(dtype).type(fill),
            "dimension_separator": sep,
            "write_empty_chunks": not sparse,
        }
        if kind == "array":
            write_array(f"{outdir}/{name}", data, chunks, options)
        else:
            level1 = write_ome(f"{outdir}/{name}", name, data, chunks, options)
            level1.astype(np.dtype(dtype).newbyteorder("<")).tofile(f"{outdir}/{name}.level1.raw")


if __name__ == "__main__":
    if len(sys.argv) < 6:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5:])
