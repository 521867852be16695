"""Writes HDF5 files with h5py (the independent writer of the HDF5 reader's tests).

Usage: write_hdf5.py file=OUT.h5 [patch_filter=ID] DATASET... [file=OUT2.h5 DATASET...]...

Each DATASET is one argument of space-separated key=value pairs:
  name=/entry/data/volume   the dataset's path; groups on the way are created
  raw=PATH dtype=uint16     the voxels: a raw file, C order [z][y][x], of that NumPy dtype;
                            without raw= the dataset is declared only: no voxel (and, chunked,
                            no chunk) is written, and it reads as its fill value
  first=N                   declared only but for its first N voxels (x), set to 7
  shape=Z,Y,X               its shape (any rank: shape=5,6 writes a 2D dataset)
  store=>u2                 the dtype stored in the file (default: dtype), e.g. >f4 or <i8
  layout=contiguous|chunked|compact   (default contiguous)
  chunks=CZ,CY,CX gzip=LEVEL shuffle=1   chunked layout options
  um=Z,Y,X                  an element_size_um attribute (micrometres, any count)
or name=/link external=OTHER.h5:/path, an external link to a dataset of another file.

patch_filter=ID rewrites, after writing, the file's one gzip filter entry (h5py writes filter
pipeline messages of version 1: id, name length, flags, value count, name, values) into filter
ID named "private", marked mandatory: a dataset whose filter is not registered, which h5py
refuses to write directly.
"""
import struct
import sys

import h5py
import numpy as np


def ints(text):
    return tuple(int(v) for v in text.split(","))


def write_dataset(f, spec):
    opts = dict(item.split("=", 1) for item in spec.split())
    if "external" in opts:
        other, path = opts["external"].split(":", 1)
        f[opts["name"]] = h5py.ExternalLink(other, path)
        return
    store = np.dtype(opts.get("store", opts["dtype"]))
    layout = opts.get("layout", "contiguous")
    name = opts["name"]
    if "raw" not in opts:
        chunks = ints(opts["chunks"]) if layout == "chunked" else None
        dset = f.create_dataset(name, shape=ints(opts["shape"]), dtype=store, chunks=chunks)
        if "first" in opts:
            dset[0, 0, :int(opts["first"])] = 7
        return
    data = np.fromfile(opts["raw"], dtype=opts["dtype"]).reshape(ints(opts["shape"]))
    if layout == "compact":
        dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
        dcpl.set_layout(h5py.h5d.COMPACT)
        space = h5py.h5s.create_simple(data.shape)
        parent = f.require_group(name.rsplit("/", 1)[0] or "/")
        dsid = h5py.h5d.create(parent.id, name.rsplit("/", 1)[1].encode(),
                               h5py.h5t.py_create(store), space, dcpl=dcpl)
        dset = h5py.Dataset(dsid)
        dset[...] = data.astype(store)
    elif layout == "chunked":
        dset = f.create_dataset(name, data=data.astype(store), chunks=ints(opts["chunks"]),
                                compression="gzip" if "gzip" in opts else None,
                                compression_opts=int(opts["gzip"]) if "gzip" in opts else None,
                                shuffle=opts.get("shuffle") == "1")
    else:
        dset = f.create_dataset(name, data=data.astype(store))
    assert dset.id.get_create_plist().get_layout() == {
        "contiguous": h5py.h5d.CONTIGUOUS, "chunked": h5py.h5d.CHUNKED,
        "compact": h5py.h5d.COMPACT}[layout]
    if "um" in opts:
        dset.attrs["element_size_um"] = np.array([float(v) for v in opts["um"].split(",")])


def patch_filter(path, filter_id):
    gzip_entry = struct.pack("<HHHH", 1, 8, 1, 1) + b"deflate\0"
    data = open(path, "rb").read()
    if data.count(gzip_entry) != 1:
        sys.exit(f"{path}: expected one version-1 gzip filter entry, found {data.count(gzip_entry)}")
    patched = struct.pack("<HHHH", filter_id, 8, 0, 1) + b"private\0"
    open(path, "wb").write(data.replace(gzip_entry, patched))


def main(args):
    files = []  # (path, patch id or None, dataset specs)
    for arg in args:
        if arg.startswith("file="):
            words = dict(item.split("=", 1) for item in arg.split())
            files.append((words["file"], words.get("patch_filter"), []))
        else:
            files[-1][2].append(arg)
    for path, patch, specs in files:
        with h5py.File(path, "w") as f:
            for spec in specs:
                write_dataset(f, spec)
        if patch:
            patch_filter(path, int(patch))


if __name__ == "__main__":
    main(sys.argv[1:])
