#!/usr/bin/python3
"""Ingest at disk speed, format by format.

Generates one multi-gigabyte volume (the project's synth:phantom generator, ingested and
extracted back to raw), writes it in every input format brickcast reads (tifffile, zarr and
h5py write TIFF, Zarr and HDF5; the MetaImage and .vti headers are a few lines written here
around the same raw bytes), and ingests each with `brickcast ingest --stats`. Prints, per
format: MB/s of input read (the file's bytes) and of voxels ingested, bricks written per
second, the peak RSS of the ingest (with its parser child, when it has one), and where the
time went (read + decode, cutting bricks, zstd, writing); beside them the ceilings of this
machine on the same bytes: `cat` (read only), `cp` (read and write) and `zstd -T2` at the
ingest's level. Each command starts with a cold page cache when the script may drop it (root).

Needs /usr/bin/python3 with numpy, tifffile, zarr, numcodecs and h5py, and /usr/bin/time
(Debian packages).

    /usr/bin/python3 bench/ingest/formats_bench.py --brickcast build/tools/brickcast \\
        --work /var/tmp/bc-ingest [--dims 1536,1536,920] [--formats raw,tiff,...] [--json F]

The default dims are 4.04 GiB of u16. The work folder needs about three times that free.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

FORMATS = ["raw", "tiff", "tiff-folder", "zarr", "hdf5", "mha", "vti"]


def log(*args):
    print(*args, file=sys.stderr, flush=True)


def drop_caches(enabled):
    """Empties the page cache so that every command reads from the disk; False when not root."""
    if not enabled:
        return False
    try:
        os.sync()
        with open("/proc/sys/vm/drop_caches", "w") as f:
            f.write("3\n")
        return True
    except OSError:
        return False


def run(cmd, cold, stdout=None):
    """Runs cmd; returns wall seconds and the peak RSS in MiB of it and its reaped children
    (the sandboxed parser's child). Measured by /usr/bin/time, a small process: Linux keeps the
    high-water RSS of the image a process had before exec, so a child forked straight from this
    script (gigabytes of memory-mapped volume) would report this script's peak as its own."""
    dropped = drop_caches(cold)
    with tempfile.NamedTemporaryFile("r", suffix=".rss") as rss:
        start = time.monotonic()
        status = subprocess.run(["/usr/bin/time", "-f", "%M", "-o", rss.name] + cmd,
                                stdout=stdout).returncode
        wall = time.monotonic() - start
        if status != 0:
            raise SystemExit(f"failed ({status}): {' '.join(cmd)}")
        kib = int(rss.read().split()[-1])
    return wall, kib / 1024.0, dropped


def file_bytes(path):
    if os.path.isdir(path):
        return sum(os.path.getsize(os.path.join(d, f)) for d, _, fs in os.walk(path) for f in fs)
    return os.path.getsize(path)


def make_source(brickcast, work, dims):
    """The phantom as raw u16, named so that brickcast reads its dims and type from the name."""
    x, y, z = dims
    raw = os.path.join(work, f"phantom_{x}x{y}x{z}_uint16.raw")
    if os.path.exists(raw) and os.path.getsize(raw) == x * y * z * 2:
        return raw
    store = os.path.join(work, "phantom.bcs")
    log(f"generating the {x}x{y}x{z} phantom ...")
    subprocess.run([brickcast, "ingest", "synth:phantom", "--dims", f"{x},{y},{z}", "-o", store,
                    "-q"], check=True)
    subprocess.run([brickcast, "extract", store, "-o", raw], check=True, stdout=subprocess.DEVNULL)
    os.remove(store)
    return raw


def slabs(volume, depth):
    for z in range(0, volume.shape[0], depth):
        yield z, np.asarray(volume[z:z + depth])


def write_format(fmt, raw, volume, work):
    """Writes `volume` (a memmap of raw, shape z, y, x) as fmt; returns (path, extra args)."""
    z, y, x = volume.shape
    if fmt == "raw":
        return raw, []
    if fmt == "tiff":
        import tifffile
        path = os.path.join(work, "phantom.tif")
        with tifffile.TiffWriter(path, bigtiff=True) as tw:
            for k in range(z):
                tw.write(volume[k], contiguous=False, photometric="minisblack")
        return path, []
    if fmt == "tiff-folder":
        import tifffile
        path = os.path.join(work, "phantom_slices")
        os.makedirs(path, exist_ok=True)
        for k in range(z):
            tifffile.imwrite(os.path.join(path, f"slice{k}.tif"), volume[k],
                             photometric="minisblack")
        return path, []
    if fmt == "zarr":
        import numcodecs
        import zarr
        path = os.path.join(work, "phantom.zarr")
        blosc = numcodecs.Blosc(cname="lz4", clevel=5, shuffle=numcodecs.Blosc.SHUFFLE)
        arr = zarr.open(path, mode="w", shape=(z, y, x), chunks=(32, 256, 256),
                        dtype=volume.dtype, compressor=blosc)
        for k, slab in slabs(volume, 32):
            arr[k:k + slab.shape[0]] = slab
        return path, []
    if fmt == "hdf5":
        import h5py
        path = os.path.join(work, "phantom.h5")
        with h5py.File(path, "w") as f:
            d = f.create_dataset("/scan/volume", shape=(z, y, x), dtype=volume.dtype,
                                 chunks=(32, 256, 256), compression="gzip",
                                 compression_opts=1, shuffle=True)
            for k, slab in slabs(volume, 32):
                d[k:k + slab.shape[0]] = slab
        return path, ["--dataset", "/scan/volume"]
    if fmt == "mha":
        path = os.path.join(work, "phantom.mha")
        header = ("ObjectType = Image\nNDims = 3\nBinaryData = True\n"
                  "BinaryDataByteOrderMSB = False\nCompressedData = False\n"
                  f"DimSize = {x} {y} {z}\nElementSpacing = 1 1 1\nElementType = MET_USHORT\n"
                  "ElementDataFile = LOCAL\n")
        with open(path, "wb") as out, open(raw, "rb") as src:
            out.write(header.encode())
            shutil.copyfileobj(src, out, 16 << 20)
        return path, []
    if fmt == "vti":
        path = os.path.join(work, "phantom.vti")
        nbytes = x * y * z * 2
        header = ('<?xml version="1.0"?>\n'
                  '<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian" '
                  'header_type="UInt64">\n'
                  f'  <ImageData WholeExtent="0 {x - 1} 0 {y - 1} 0 {z - 1}" Origin="0 0 0" '
                  'Spacing="1 1 1">\n'
                  f'    <Piece Extent="0 {x - 1} 0 {y - 1} 0 {z - 1}">\n'
                  '      <PointData Scalars="density">\n'
                  '        <DataArray type="UInt16" Name="density" format="appended" '
                  'offset="0"/>\n'
                  '      </PointData>\n    </Piece>\n  </ImageData>\n'
                  '  <AppendedData encoding="raw">\n   _')
        with open(path, "wb") as out, open(raw, "rb") as src:
            out.write(header.encode())
            out.write(np.uint64(nbytes).tobytes())
            shutil.copyfileobj(src, out, 16 << 20)
            out.write(b"\n  </AppendedData>\n</VTKFile>\n")
        return path, []
    raise SystemExit(f"unknown format {fmt}")


def remove(path):
    if os.path.isdir(path):
        shutil.rmtree(path)
    elif os.path.exists(path):
        os.remove(path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--brickcast", required=True)
    ap.add_argument("--work", required=True, help="scratch folder (about 3x the volume free)")
    ap.add_argument("--dims", default="1536,1536,920")
    ap.add_argument("--formats", default=",".join(FORMATS))
    ap.add_argument("--warm", action="store_true", help="do not drop the page cache")
    ap.add_argument("--keep", action="store_true", help="keep the written inputs")
    ap.add_argument("--json", help="write the results as JSON")
    args = ap.parse_args()
    dims = [int(v) for v in args.dims.split(",")]
    formats = args.formats.split(",")
    os.makedirs(args.work, exist_ok=True)
    cold = not args.warm
    brickcast = os.path.abspath(args.brickcast)

    raw = make_source(brickcast, args.work, dims)
    nbytes = os.path.getsize(raw)
    volume = np.memmap(raw, dtype=np.uint16, mode="r", shape=(dims[2], dims[1], dims[0]))
    ceilings = {}
    wall, _, dropped = run(["cat", raw], cold, stdout=subprocess.DEVNULL)
    ceilings["cat (read)"] = nbytes / 1e6 / wall
    copy = os.path.join(args.work, "copy.raw")
    wall, _, _ = run(["cp", raw, copy], cold)
    ceilings["cp (read + write)"] = nbytes / 1e6 / wall
    os.remove(copy)
    wall, _, _ = run(["zstd", "-T2", "-3", "-q", "-f", raw, "-o", copy + ".zst"], cold)
    ceilings["zstd -T2 -3 (read, compress, write)"] = nbytes / 1e6 / wall
    os.remove(copy + ".zst")

    rows = []
    for fmt in formats:
        log(f"{fmt}: writing ...")
        t = time.monotonic()
        path, extra = write_format(fmt, raw, volume, args.work)
        written = time.monotonic() - t
        store = os.path.join(args.work, "out.bcs")
        stats = os.path.join(args.work, "stats.json")
        log(f"{fmt}: ingesting {path} ...")
        wall, rss, _ = run([brickcast, "ingest", path, "-o", store, "--stats", stats, "-q"] +
                           extra, cold)
        with open(stats) as f:
            s = json.load(f)
        rows.append({"format": fmt, "inputBytes": file_bytes(path), "sourceBytes": s["sourceBytes"],
                     "wallS": wall, "peakRssMiB": rss, "bricks": s["bricks"],
                     "storedBytes": s["storedBytes"], "times": s["times"],
                     "writeS": written})
        remove(store)
        if fmt != "raw" and not args.keep:
            remove(path)

    cpu = os.cpu_count()
    print(f"\nbrickcast ingest, {dims[0]}x{dims[1]}x{dims[2]} u16 phantom "
          f"({nbytes / 2**30:.2f} GiB), {cpu} cores, default bricks (64 + 2), zstd level 3; "
          f"page cache {'dropped before each command' if dropped else 'warm'}\n")
    print("| ceiling on the same bytes | MB/s |\n|---|---:|")
    for k, v in ceilings.items():
        print(f"| {k} | {v:.0f} |")
    zstd = ceilings["zstd -T2 -3 (read, compress, write)"]
    print("\n| format | input GB | s | input MB/s | voxel MB/s | ÷ zstd -T2 | bricks/s "
          "| peak RSS MiB | read+decode s | slices s | ring wait s | cut s (sum) "
          "| compress s (sum) | write s (sum) | histogram s |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        t = r["times"]
        voxel = r["sourceBytes"] / 1e6 / r["wallS"]
        print(f"| {r['format']} | {r['inputBytes'] / 1e9:.2f} | {r['wallS']:.1f} "
              f"| {r['inputBytes'] / 1e6 / r['wallS']:.0f} | {voxel:.0f} | {voxel / zstd:.2f} "
              f"| {r['bricks'] / r['wallS']:.0f} | {r['peakRssMiB']:.0f} | {t['read']:.1f} "
              f"| {t['cut']:.1f} | {t['ringWait']:.1f} | {t['brickCut']:.1f} "
              f"| {t['compress']:.1f} "
              f"| {t['write']:.1f} | {t['histogram']:.1f} |")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"dims": dims, "bytes": nbytes, "cores": cpu, "coldCache": dropped,
                       "ceilingsMBs": ceilings, "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
