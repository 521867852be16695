#!/usr/bin/python3
"""Independent TIFF writers for TiffReaderTest: tifffile (numpy) and libtiff's tiffcp.

  write_tiff.py roundtrip RAW DTYPE NX NY NZ OUT VARIANT...
      Writes the raw volume RAW (x fastest, little endian) as each VARIANT: OUT/VARIANT.tif,
      or the folder OUT/VARIANT/ for the folder_* variants.
  write_tiff.py cases OUT
      Writes the small files of the direct reader tests into OUT, each good one beside the
      raw voxels it holds (NAME.raw), and the bad inputs.

tifffile 2023.2.3 writes LZW and zstd only with imagecodecs, which Debian does not ship, so
those variants are tifffile's uncompressed output recompressed by tiffcp (libtiff-tools).
"""
import os
import shutil
import subprocess
import sys

import numpy as np
import tifffile


def tiffcp(src, dst, *options):
    subprocess.run(["tiffcp", *options, src, dst], check=True)


def float_or_int(volume, integer, floating):
    """The predictor tiffcp applies: horizontal for integers, floating point for floats."""
    return floating if volume.dtype.kind == "f" else integer


def write_variant(volume, out, variant):
    path = os.path.join(out, variant + ".tif")
    plain = dict(photometric="minisblack")
    if variant == "strips_be":
        # Classic TIFF, big endian, uncompressed, 13-row strips (the last one short).
        tifffile.imwrite(path, volume, byteorder=">", rowsperstrip=13, **plain)
    elif variant == "bigtiff_zlib_tiles":
        # Edge tiles hang over the image on both axes unless its size is a multiple of 64.
        tifffile.imwrite(path, volume, bigtiff=True, tile=(64, 64), compression="zlib",
                         **plain)
    elif variant == "legacy_deflate_be":
        # Deflate under its old code, 32946, with the horizontal predictor, big endian.
        tifffile.imwrite(path, volume, byteorder=">", compression=32946, predictor=True,
                         **plain)
    elif variant == "lzw_strips":
        tmp = path + ".in.tif"
        tifffile.imwrite(tmp, volume, **plain)
        tiffcp(tmp, path, "-c", "lzw:" + float_or_int(volume, "2", "3"), "-r", "16")
        os.remove(tmp)
    elif variant == "zstd_tiles":
        tmp = path + ".in.tif"
        tifffile.imwrite(tmp, volume, **plain)
        tiffcp(tmp, path, "-8", "-c", "zstd:" + float_or_int(volume, "2", "3"),
               "-t", "-w", "32", "-l", "48")
        os.remove(tmp)
    elif variant == "zstd_strips":
        # Little endian: libtiff 4.5 writes the floating-point predictor wrongly into a
        # big-endian file (tiffcp -B), though it reads a correct one.
        tmp = path + ".in.tif"
        tifffile.imwrite(tmp, volume, **plain)
        tiffcp(tmp, path, "-c", "zstd:" + float_or_int(volume, "2", "3"), "-r", "8")
        os.remove(tmp)
    elif variant == "folder_zlib_tiles":
        # Unpadded names (natural order is not byte order), mixed-case extensions and a file
        # that is no slice.
        folder = os.path.join(out, variant)
        os.makedirs(folder)
        for z, plane in enumerate(volume):
            name = "s%d.%s" % (z, "tif" if z % 2 == 0 else "TIFF")
            tifffile.imwrite(os.path.join(folder, name), plane, tile=(16, 16),
                             compression="zlib", predictor=True, **plain)
        with open(os.path.join(folder, "notes.txt"), "w") as f:
            f.write("not a slice\n")
    elif variant == "bigtiff_strips":
        # The benchmark's layout: BigTIFF, little endian, uncompressed, a page at a time, so
        # the pages' strips lie apart (the parent reads them itself, located by the parser).
        with tifffile.TiffWriter(path, bigtiff=True) as w:
            for plane in volume:
                w.write(plane, contiguous=False, **plain)
    elif variant == "folder_mixed":
        # Slices the parent reads itself (uncompressed little endian, 5-row strips) between
        # slices the parser decodes (deflate; uncompressed big endian), in one folder.
        folder = os.path.join(out, variant)
        os.makedirs(folder)
        for z, plane in enumerate(volume):
            name = os.path.join(folder, "p%03d.tif" % z)
            if z % 4 == 1:
                tifffile.imwrite(name, plane, compression="zlib", **plain)
            elif z % 4 == 3:
                tifffile.imwrite(name, plane, byteorder=">", **plain)
            else:
                tifffile.imwrite(name, plane, rowsperstrip=5, **plain)
    elif variant == "folder_lzw_tiles":
        folder = os.path.join(out, variant)
        os.makedirs(folder)
        tmp = os.path.join(out, "plane.tif")
        for z, plane in enumerate(volume):
            tifffile.imwrite(tmp, plane, **plain)
            tiffcp(tmp, os.path.join(folder, "slice_%d.tiff" % (z + 1)),
                   "-c", "lzw:" + float_or_int(volume, "2", "3"), "-t", "-w", "16", "-l", "32")
        os.remove(tmp)
    else:
        raise SystemExit("unknown variant " + variant)


def roundtrip(raw, dtype, nx, ny, nz, out, variants):
    volume = np.fromfile(raw, dtype=np.dtype(dtype).newbyteorder("<"))
    volume = volume.reshape(int(nz), int(ny), int(nx)).astype(np.dtype(dtype))
    for variant in variants:
        write_variant(volume, out, variant)


def pattern(shape, dtype):
    """Voxels that differ in every byte of multi-byte types, reproducibly."""
    i = np.arange(int(np.prod(shape)), dtype=np.int64).reshape(shape)
    if dtype == np.float32:
        return (i * 0.25 - 3.5).astype(np.float32)
    if dtype == np.int16:
        return (i * 997 - 20000).astype(np.int64).astype(np.int16)
    if dtype == np.uint16:
        return (i * 1237 + 5).astype(np.uint16)
    return (i * 37 + 11).astype(np.uint8)


def good(out, name, volume, **options):
    tifffile.imwrite(os.path.join(out, name + ".tif"), volume, photometric="minisblack",
                     **options)
    volume.astype(volume.dtype.newbyteorder("<")).tofile(os.path.join(out, name + ".raw"))


def mixed_folder(out, name, odd_plane):
    """s1..s4.tif of 20x16 u16, but s3.tif is `odd_plane`."""
    folder = os.path.join(out, name)
    os.makedirs(folder)
    for z in range(1, 5):
        plane = odd_plane if z == 3 else pattern((16, 20), np.uint16)
        tifffile.imwrite(os.path.join(folder, "s%d.tif" % z), plane, photometric="minisblack")


def strip_data(path, page):
    with tifffile.TiffFile(path) as tif:
        p = tif.pages[page]
        return list(p.dataoffsets), list(p.databytecounts)


def good_cases(out):
    # ImageJ: resolution in pixels per micron (ResolutionUnit none), z spacing in microns.
    good(out, "imagej_um", pattern((7, 30, 40), np.uint16), imagej=True,
         resolution=(2.0, 4.0), metadata={"spacing": 2.5, "unit": "um", "axes": "ZYX"})
    good(out, "cm_i16", pattern((5, 30, 40), np.int16), resolution=(2.0, 4.0),
         resolutionunit="CENTIMETER", rowsperstrip=4)
    good(out, "inch_f32_tiles", pattern((6, 30, 40), np.float32), resolution=(254.0, 127.0),
         resolutionunit="INCH", tile=(16, 16), compression="zlib", byteorder=">")
    good(out, "u8_pages", pattern((9, 11, 13), np.uint8), compression="zlib", rowsperstrip=3)


def bad_cases(out):
    mixed_folder(out, "mixed_width", pattern((16, 21), np.uint16))
    mixed_folder(out, "mixed_length", pattern((17, 20), np.uint16))
    mixed_folder(out, "mixed_type", pattern((16, 20), np.uint8))
    with tifffile.TiffWriter(os.path.join(out, "page_width.tif")) as w:
        for z in range(4):
            w.write(pattern((16, 21 if z == 2 else 20), np.uint16), photometric="minisblack",
                    contiguous=False)
    # Five deflate pages, cut inside the last page's last strip: every page header survives.
    path = os.path.join(out, "truncated.tif")
    tifffile.imwrite(path, pattern((5, 64, 48), np.uint16), compression="zlib",
                     rowsperstrip=16, photometric="minisblack")
    offsets, counts = strip_data(path, 4)
    os.truncate(path, offsets[-1] + counts[-1] // 2)
    # A deflate page whose second strip claims more bytes than the file holds (compressed:
    # libtiff replaces a bogus count of an uncompressed strip by its own estimate).
    path = os.path.join(out, "beyond.tif")
    tifffile.imwrite(path, pattern((16, 20), np.uint16), compression="zlib", rowsperstrip=4,
                     photometric="minisblack")
    with tifffile.TiffFile(path) as tif:
        tag = tif.pages[0].tags["StripByteCounts"]
        size = {3: 2, 4: 4}[tag.dtype]  # SHORT or LONG counts, outside the IFD entry
        where = tag.valueoffset + size
    with open(path, "r+b") as f:
        f.seek(where)
        f.write((65000).to_bytes(size, "little"))
    # Deflate data overwritten inside the file: libtiff's own decode error must surface.
    path = os.path.join(out, "corrupt_deflate.tif")
    tifffile.imwrite(path, pattern((2, 32, 32), np.uint16), compression="zlib",
                     photometric="minisblack")
    offsets, counts = strip_data(path, 1)
    with open(path, "r+b") as f:
        f.seek(offsets[0])
        f.write(b"\xff" * counts[0])
    rgb = pattern((16, 20, 3), np.uint8)
    tifffile.imwrite(os.path.join(out, "rgb.tif"), rgb, photometric="rgb")
    tifffile.imwrite(os.path.join(out, "bilevel.tif"), pattern((16, 24), np.uint8) > 100,
                     photometric="minisblack")
    tifffile.imwrite(os.path.join(out, "uint32.tif"), pattern((16, 20), np.uint16).astype(
        np.uint32), photometric="minisblack")
    tifffile.imwrite(os.path.join(out, "float64.tif"), pattern((16, 20), np.float32).astype(
        np.float64), photometric="minisblack")
    colormap = np.tile(np.arange(256, dtype=np.uint16) * 257, (3, 1))
    tifffile.imwrite(os.path.join(out, "palette.tif"), pattern((16, 20), np.uint8),
                     photometric="palette", colormap=colormap)
    tifffile.imwrite(os.path.join(out, "hyperstack.tif"), pattern((2, 16, 20), np.uint16),
                     imagej=True, metadata={"axes": "CYX"})
    nan = pattern((3, 16, 20), np.float32)
    nan[1, 2, 3] = np.nan
    tifffile.imwrite(os.path.join(out, "nan.tif"), nan, photometric="minisblack")
    with open(os.path.join(out, "not_a_tiff.tif"), "w") as f:
        f.write("Hello, this is a text file with a .tif name.\n")
    os.makedirs(os.path.join(out, "empty"))
    if shutil.which("tiffcp"):
        tmp = os.path.join(out, "plain_u8.tif")
        tifffile.imwrite(tmp, pattern((32, 32), np.uint8), photometric="minisblack")
        tiffcp(tmp, os.path.join(out, "jpeg.tif"), "-c", "jpeg")
        os.remove(tmp)


def main(argv):
    if len(argv) >= 8 and argv[1] == "roundtrip":
        roundtrip(argv[2], argv[3], argv[4], argv[5], argv[6], argv[7], argv[8:])
    elif len(argv) == 3 and argv[1] == "cases":
        good_cases(argv[2])
        bad_cases(argv[2])
    else:
        raise SystemExit(__doc__)


if __name__ == "__main__":
    main(sys.argv)
