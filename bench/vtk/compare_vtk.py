#!/usr/bin/env python3
"""brickcast against VTK: time and error against the converged float64 reference.

What it does, for every scan x preset x view x size (--scans, --tfs, --views, --sizes)
  1. Loads the raw scan (../shared/data; cthead, headsq, CT_AVM, frog, hydrogen; the DICOM
     pancreas series and the NIfTI Iguana as brickcast ingests and extracts them to raw) into
     vtkImageData, and ingests the same raw file into a brickcast store (cached in OUT/stores).
  2. Rebuilds brickcast's camera (Camera::orbit + ViewBasis), the scan's presets (configs/tf,
     placed exactly as render/TransferFunction.cpp places them from the store's own histogram,
     sampled into brickcast's 4096-entry table; the preset's "shading" default honoured on both
     sides) and optical model (render/OPTICS.md: per-unit-step opacity, headlight Blinn-Phong
     ambient 0.3, diffuse 0.7, specular 0.25, shininess 24, black background, trilinear) in VTK.
  3. The true image: `brickcast render --reference --converge` (render/ConvergedReference.h):
     the float64 reference at --conv-start, halved until the image changes by under --conv-tol
     (max abs, RGBA) or --conv-floor / --conv-time-s is reached (then marked NOT converged).
     It and the same-step references are cached in OUT/refcache under a hash of everything that
     determines them (scan bytes, TF file, view, size, shading, step or convergence settings,
     and the model: the pixels of a 64^2 reference probe of the same view, so a rebuilt
     brickcast keeps them unless its reference draws differently), so reruns skip them.
     --refs-only makes them and stops, timing nothing.
  4. Times VTK's CPU raycaster (vtkFixedPointVolumeRayCastMapper) at --step: --warmup frames,
     then the median of --frames frames (render + framebuffer read-back); the first is the
     cold frame.
  5. Times brickcast's CPU raycaster at every --bc-steps step the same way (one `brickcast
     render --renderer cpu --repeat` per step; median of the --stats frameMs after the warm-up).
     The same step is --step; the equal-error point is the fastest step whose RMSE against the
     converged image is no worse than VTK's.
  6. Every error is linear [0,1] RGB over all pixels of 8-bit PNGs, against the converged
     reference and against the reference at the renderer's own step. brickcast writes
     premultiplied RGBA (RGB already over black); VTK renders over black: alpha is ignored.
     Prints markdown tables (also OUT/table.md) and writes every number to OUT/results.json
     (rewritten after every pair, so an interrupted run keeps what it measured).

How to run (from the repository root; Debian 12):
    apt-get install python3-vtk9 xvfb          # benchmark-only peer, not a project dependency
    python3 bench/vtk/compare_vtk.py --brickcast build/tools/brickcast --out /tmp/vtkcmp

Debian's VTK 9.1 is built for X only (no EGL/OSMesa offscreen): without $DISPLAY the script
re-runs itself under `xvfb-run -a` (and under /usr/bin/python3 when the current python3, e.g.
a pyenv one, cannot import Debian's vtk). It installs nothing; without vtk it says how to
install it and exits 2.
"""

import argparse
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.normpath(os.path.join(HERE, "..", ".."))
DEFAULT_DATA_DIR = os.path.normpath(os.path.join(REPO, "..", "shared", "data"))

INSTALL_HINT = ("VTK for Python is missing. On Debian 12:\n"
                "    apt-get install python3-vtk9 python3-numpy xvfb\n"
                "(it installs for /usr/bin/python3; the script re-runs itself with that "
                "interpreter when it can import vtk)")


# ---- environment: the right interpreter, an X display --------------------------------------

def _can_import_vtk(python):
    try:
        return subprocess.run([python, "-c", "import vtk, numpy"], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL, timeout=120).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


def ensure_environment():
    """Re-executes under Debian's python3 and/or xvfb-run when needed; exits 2 without vtk."""
    try:
        import numpy  # noqa: F401
        import vtk  # noqa: F401
    except ImportError:
        system_python = "/usr/bin/python3"
        if (os.environ.get("BC_VTK_REEXEC_PY") != "1" and os.path.exists(system_python)
                and os.path.realpath(sys.executable) != os.path.realpath(system_python)
                and _can_import_vtk(system_python)):
            print(f"[compare_vtk] {sys.executable} cannot import vtk; re-running with "
                  f"{system_python}", flush=True)
            env = dict(os.environ, BC_VTK_REEXEC_PY="1")
            os.execve(system_python, [system_python] + sys.argv, env)
        print(INSTALL_HINT, file=sys.stderr)
        sys.exit(2)
    if not os.environ.get("DISPLAY") and os.environ.get("BC_VTK_REEXEC_X") != "1":
        xvfb = shutil.which("xvfb-run")
        if not xvfb:
            print("No $DISPLAY and no xvfb-run: Debian's VTK 9.1 needs an X display even for "
                  "offscreen rendering. Install it with: apt-get install xvfb", file=sys.stderr)
            sys.exit(2)
        print("[compare_vtk] no $DISPLAY: re-running under xvfb-run -a", flush=True)
        env = dict(os.environ, BC_VTK_REEXEC_X="1")
        os.execve(xvfb, [xvfb, "-a", "-s", "-screen 0 1280x1024x24", sys.executable]
                  + sys.argv, env)


# ---- brickcast's camera (render/Camera.cpp) -------------------------------------------------

def orbit_camera(box_max, az_deg, el_deg, dist=1.0, fov_deg=30.0, up=None):
    """Camera::orbit for the box [0, box_max]: eye, target, up, fov (degrees, vertical)."""
    az, el = math.radians(az_deg), math.radians(el_deg)
    d = (math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el))
    centre = tuple(0.5 * m for m in box_max)
    radius = 0.5 * math.sqrt(sum(m * m for m in box_max))
    fit = radius / math.sin(0.5 * math.radians(fov_deg))
    eye = tuple(c + di * fit * dist for c, di in zip(centre, d))
    if up is None:
        up = (0.0, 1.0, 0.0) if abs(math.sin(el)) > 0.999 else (0.0, 0.0, 1.0)
    return {"eye": eye, "target": centre, "up": tuple(up), "fov": fov_deg}


def parse_view(text):
    """'AZ,EL[,DIST][/UX,UY,UZ]' -> dict(orbit=[...], up=[...] or None, name)."""
    orbit, _, up = text.partition("/")
    nums = [float(v) for v in orbit.split(",")]
    if len(nums) not in (2, 3):
        raise argparse.ArgumentTypeError(f"view '{text}': expected AZ,EL[,DIST][/UX,UY,UZ]")
    upv = [float(v) for v in up.split(",")] if up else None
    if upv is not None and len(upv) != 3:
        raise argparse.ArgumentTypeError(f"view '{text}': up needs 3 numbers")
    name = "az%g_el%g" % (nums[0], nums[1]) + (f"_d{nums[2]:g}" if len(nums) > 2 else "")
    if upv:
        name += "_up" + "_".join("%g" % u for u in upv)
    return {"orbit": nums, "up": upv, "name": name, "text": text}


# ---- brickcast's transfer function (render/TransferFunction.cpp) ----------------------------

class StoreStats:
    def __init__(self, info):
        self.vmin = float(info["value_min"])
        self.vmax = float(info["value_max"])
        self.hist = [int(c) for c in info["histogram"]]

    def percentile(self, percent):
        hist = self.hist
        mode = max(range(len(hist)), key=lambda i: (hist[i], -i))  # first of equals
        first = mode + 1
        total = float(sum(hist[first:]))
        if total == 0.0:
            first, total = 0, float(sum(hist))
        bin_width = (self.vmax - self.vmin) / len(hist)
        target = percent / 100.0 * total
        below = 0.0
        for i in range(first, len(hist)):
            count = float(hist[i])
            if count == 0.0:
                continue
            if below + count >= target:
                return min(self.vmax, self.vmin + (i + (target - below) / count) * bin_width)
            below += count
        return self.vmax


def load_tf(path, stats):
    with open(path) as f:
        doc = json.load(f)
    points = []
    for p in doc["points"]:
        rgba = [float(c) for c in p["rgba"]]
        if "value" in p:
            v = float(p["value"])
        elif "fraction" in p:
            v = stats.vmin + float(p["fraction"]) * (stats.vmax - stats.vmin)
        else:
            v = stats.percentile(float(p["percentile"]))
        points.append((v, rgba))
    points.sort(key=lambda q: q[0])  # stable, as std::stable_sort
    dmin = stats.vmin
    dmax = stats.vmax if stats.vmax > stats.vmin else stats.vmin + 1.0
    return {"name": doc.get("name", os.path.basename(path)), "points": points,
            "domain": (dmin, dmax), "shading": bool(doc.get("shading", True))}


def tf_evaluate(points, value):
    import bisect
    values = [p[0] for p in points]
    k = bisect.bisect_right(values, value)  # upper_bound
    if k == 0:
        return list(points[0][1])
    if k == len(points):
        return list(points[-1][1])
    (va, ca), (vb, cb) = points[k - 1], points[k]
    t = (value - va) / (vb - va)
    return [a * (1.0 - t) + b * t for a, b in zip(ca, cb)]


def tf_table(tf, entries=4096):
    """TransferFunction::table without the opacity correction (VTK does that itself from the
    scalar opacity unit distance): (values, rgba rows), snapPeaks included."""
    dmin, dmax = tf["domain"]
    span, last = dmax - dmin, entries - 1
    values = [dmax if i == last else dmin + span * (i / last) for i in range(entries)]
    rgba = [tf_evaluate(tf["points"], v) for v in values]
    for v, c in tf["points"]:
        u = (v - dmin) / span * last
        if not (0.0 < u < last):
            continue
        k = min(int(u), entries - 2)
        if c[3] <= max(rgba[k][3], rgba[k + 1][3]):
            continue
        rgba[k if u - k < 0.5 else k + 1] = list(c)
    return values, rgba


# ---- VTK -----------------------------------------------------------------------------------

RAW_TYPES = {"u8": ("<u1", "VTK_UNSIGNED_CHAR"), "u16": ("<u2", "VTK_UNSIGNED_SHORT"),
             "i16": ("<i2", "VTK_SHORT"), "f32": ("<f4", "VTK_FLOAT")}


def load_volume(vtk, np, path, dims, spacing, pad, voxel_type="u16"):
    from vtk.util import numpy_support
    nx, ny, nz = dims
    dtype, vtk_type = RAW_TYPES[voxel_type]
    data = np.fromfile(path, dtype=dtype)
    if data.size != nx * ny * nz:
        raise SystemExit(f"{path}: {data.size} voxels, expected {nx}x{ny}x{nz}")
    vol = data.reshape(nz, ny, nx)
    image = vtk.vtkImageData()
    if pad:
        # One edge-replicated voxel on every side, cropped back to brickcast's box [0, dims*sp]
        # in the mapper: brickcast samples the half voxel beyond the outer voxel centres with
        # clamp-to-edge values, VTK only between the point bounds.
        vol = np.pad(vol, 1, mode="edge")
        origin = [-0.5 * s for s in spacing]
    else:
        origin = [0.5 * s for s in spacing]  # voxel i's centre at (i + 0.5) * spacing
    vol = np.ascontiguousarray(vol)
    image.SetDimensions(vol.shape[2], vol.shape[1], vol.shape[0])
    image.SetSpacing(*spacing)
    image.SetOrigin(*origin)
    arr = numpy_support.numpy_to_vtk(vol.ravel(), deep=True, array_type=getattr(vtk, vtk_type))
    arr.SetName("scalars")
    image.GetPointData().SetScalars(arr)
    return image


def vtk_property(vtk, tf, nodes, shade, unit_distance):
    color = vtk.vtkColorTransferFunction()
    opacity = vtk.vtkPiecewiseFunction()
    if nodes == "table":
        values, rgba = tf_table(tf)
    else:  # the control points alone (VTK's own linear interpolation, clamped at the ends)
        values, rgba = [p[0] for p in tf["points"]], [p[1] for p in tf["points"]]
    for v, c in zip(values, rgba):
        color.AddRGBPoint(v, c[0], c[1], c[2])
        opacity.AddPoint(v, c[3])
    color.ClampingOn()
    opacity.ClampingOn()
    prop = vtk.vtkVolumeProperty()
    prop.SetColor(color)
    prop.SetScalarOpacity(opacity)
    prop.SetScalarOpacityUnitDistance(unit_distance)
    prop.SetInterpolationTypeToLinear()
    prop.SetAmbient(0.3)
    prop.SetDiffuse(0.7)
    prop.SetSpecular(0.25)
    prop.SetSpecularPower(24.0)
    if shade:
        prop.ShadeOn()
    else:
        prop.ShadeOff()
    return prop


class VtkScene:
    def __init__(self, vtk, width, height):
        self.vtk = vtk
        self.window = vtk.vtkRenderWindow()
        self.window.SetOffScreenRendering(1)
        self.window.SetSize(width, height)
        self.window.SetMultiSamples(0)
        self.renderer = vtk.vtkRenderer()
        self.renderer.SetBackground(0.0, 0.0, 0.0)
        self.renderer.TwoSidedLightingOn()  # brickcast's shading is two-sided: |n . l|
        self.renderer.AutomaticLightCreationOff()
        light = vtk.vtkLight()
        light.SetLightTypeToHeadlight()
        light.SetColor(1.0, 1.0, 1.0)  # diffuse and specular colour
        # The fixed-point mapper's shading tables (vtkEncodedGradientShader) scale the
        # ambient term by the light's ambient colour, black by default; the GPU mapper's
        # headlight path ignores it. brickcast's ambient is 0.3 * colour: white ambient light.
        light.SetAmbientColor(1.0, 1.0, 1.0)
        light.SetIntensity(1.0)
        self.renderer.AddLight(light)
        self.light = light
        self.window.AddRenderer(self.renderer)
        self.volume = None

    def set_volume(self, mapper, prop):
        if self.volume is not None:
            self.renderer.RemoveVolume(self.volume)
        self.volume = self.vtk.vtkVolume()
        self.volume.SetMapper(mapper)
        self.volume.SetProperty(prop)
        self.renderer.AddVolume(self.volume)

    def set_camera(self, cam):
        c = self.renderer.GetActiveCamera()
        c.SetPosition(*cam["eye"])
        c.SetFocalPoint(*cam["target"])
        c.SetViewUp(*cam["up"])
        c.SetViewAngle(cam["fov"])  # vertical (UseHorizontalViewAngle off)
        c.ParallelProjectionOff()
        c.OrthogonalizeViewUp()
        self.renderer.ResetCameraClippingRange()

    def frame(self):
        """One timed frame: Render() and a read-back of the colour buffer (which also waits
        for the GL pipeline to finish). Returns ms."""
        t = time.perf_counter()
        self.window.Render()
        pixels = self.vtk.vtkUnsignedCharArray()
        self.window.GetRGBACharPixelData(0, 0, 0, 0, 0, pixels)  # one pixel: forces a finish
        return (time.perf_counter() - t) * 1e3

    def save_png(self, path):
        w2i = self.vtk.vtkWindowToImageFilter()
        w2i.SetInput(self.window)
        w2i.SetInputBufferTypeToRGB()
        w2i.ReadFrontBufferOff()
        w2i.Update()
        writer = self.vtk.vtkPNGWriter()
        writer.SetFileName(path)
        writer.SetInputConnection(w2i.GetOutputPort())
        writer.Write()

    def gl_renderer(self):
        text = self.window.ReportCapabilities() or ""
        for line in text.splitlines():
            if "renderer string" in line:
                return line.split(":", 1)[1].strip()
        return "?"


def make_mapper(vtk, kind, image, step_mm, crop_box, blend="composite"):
    if kind == "vtk-cpu":
        m = vtk.vtkFixedPointVolumeRayCastMapper()
        m.SetImageSampleDistance(1.0)
        m.SetMinimumImageSampleDistance(1.0)
        m.SetMaximumImageSampleDistance(1.0)
        m.SetInteractiveSampleDistance(step_mm)
    else:
        m = vtk.vtkOpenGLGPUVolumeRayCastMapper()
        m.UseJitteringOff()
    m.AutoAdjustSampleDistancesOff()
    m.LockSampleDistanceToInputSpacingOff()
    m.SetSampleDistance(step_mm)
    {"composite": m.SetBlendModeToComposite, "mip": m.SetBlendModeToMaximumIntensity,
     "minip": m.SetBlendModeToMinimumIntensity}[blend]()
    m.SetInputData(image)
    if crop_box is not None:
        m.CroppingOn()
        m.SetCroppingRegionPlanes(crop_box[0][0], crop_box[1][0], crop_box[0][1],
                                  crop_box[1][1], crop_box[0][2], crop_box[1][2])
        m.SetCroppingRegionFlagsToSubVolume()
    return m


# ---- brickcast CLI -------------------------------------------------------------------------

def run(cmd, nice=True):
    full = (["nice", "-n", "10"] if nice and shutil.which("nice") else []) + cmd
    p = subprocess.run(full, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if p.returncode != 0:
        raise SystemExit(f"command failed ({p.returncode}): {' '.join(cmd)}\n{p.stdout}")
    return p.stdout


def brickcast_render(args, store, out_png, tf, view, size, step, extra):
    stats_path = out_png[:-4] + ".json"
    cmd = [args.brickcast, "render", store, "-o", out_png, "--tf", tf,
           "--orbit", ",".join("%g" % v for v in view["orbit"]),
           "--size", f"{size},{size}", "--step", "%g" % step,
           "--fov", "%g" % args.fov, "--stats", stats_path] + extra
    if getattr(args, "blend", "composite") != "composite":  # every frame of the pair in the mode
        cmd += ["--mode", args.blend]
    if view["up"]:
        cmd += ["--up", ",".join("%g" % u for u in view["up"])]
    t = time.perf_counter()
    run(cmd)
    wall = (time.perf_counter() - t) * 1e3
    with open(stats_path) as f:
        stats = json.load(f)
    stats["wallMs"] = wall
    return stats


# ---- metrics -------------------------------------------------------------------------------

def read_rgb(vtk, np, path):
    from vtk.util import numpy_support
    r = vtk.vtkPNGReader()
    r.SetFileName(path)
    r.Update()
    img = r.GetOutput()
    w, h, _ = img.GetDimensions()
    a = numpy_support.vtk_to_numpy(img.GetPointData().GetScalars())
    a = a.reshape(h, w, -1).astype(np.float64) / 255.0
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    return a[:, :, :3]


def metrics(np, img, ref):
    d = img - ref
    rmse = float(np.sqrt(np.mean(d * d)))
    psnr = float("inf") if rmse == 0 else 20.0 * math.log10(1.0 / rmse)
    return {"psnr": psnr, "maxAbs": float(np.max(np.abs(d))), "rmse": rmse,
            "meanSigned": float(np.mean(d))}


# ---- the scans and their presets -----------------------------------------------------------

# Every scan of ../shared/data that VTK reads as raw (MANIFEST.md), with brickcast's presets for
# its modality (configs/tf/README.md, bench/BenchDatasets.cpp).
SCANS = {
    "cthead": {"file": "stanford_cthead_256x256x113_uint16.raw", "dims": (256, 256, 113),
               "type": "u16", "spacing": (1, 1, 2), "tfs": ["ct-bone", "ct-skin"]},
    "headsq": {"file": "vtk_headsq_quarter_64x64x93_uint16.raw", "dims": (64, 64, 93),
               "type": "u16", "spacing": (3.2, 3.2, 1.5), "tfs": ["ct-bone", "ct-skin"]},
    "CT_AVM": {"file": "CT_AVM_256x242x154_uint8.raw", "dims": (256, 242, 154),
               "type": "u8", "spacing": (0.72, 0.721, 1.0), "tfs": ["vessels"]},
    "frog": {"file": "frog_500x470x136_uint8.raw", "dims": (500, 470, 136),
             "type": "u8", "spacing": (1, 1, 1.5), "tfs": ["mr"]},
    "hydrogen": {"file": "hydrogen_64x64x64_float32.raw", "dims": (64, 64, 64),
                 "type": "f32", "spacing": (1, 1, 1), "tfs": ["smoke"]},
    # Containers VTK would read with readers of its own (vtkDICOMImageReader, vtkNIFTIImage-
    # Reader) whose orientation, rescaling and slice order differ from brickcast's: brickcast
    # ingests them and `brickcast extract` writes level 0 back as raw, which both then read,
    # so both render exactly the same voxels in the same frame (dims, type and spacing from
    # `brickcast info --json`).
    "pancreas": {"source": "tcia_pancreas_ct_dicom", "tfs": ["ct-bone", "ct-skin"]},
    "Iguana": {"source": "Iguana.nii.gz", "tfs": ["ct-bone"]},
}


def raw_path(args, scan):
    """The raw file both renderers read: the shared one, or the one extracted from a store."""
    spec = SCANS[scan]
    if "file" in spec:
        return os.path.join(args.data_dir, spec["file"])
    return os.path.join(args.out, "stores", scan + ".raw")

# The model (render/OPTICS.md as the float64 reference implements it) is identified by what it
# draws, not by its sources: a probe of each scan/preset/view/shading (PROBE_SIZE^2, step 1,
# `brickcast render --reference`), hashed over its decoded RGBA pixels. A rebuilt brickcast
# whose reference draws the same pixels keeps the cache (a refactor of a file the reference
# shares with the raycasters invalidates nothing); one that draws any pixel differently (TF
# placement, camera, optics, classification) makes every reference of that probe anew. The
# halving loop is not in the probe, so its sources are hashed as well.
PROBE_SIZE = 64
CONVERGENCE_SOURCES = ["render/ConvergedReference.cpp", "render/ConvergedReference.h"]


def sha256_of(path, chunk=1 << 20):
    import hashlib
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(chunk), b""):
            h.update(block)
    return h.hexdigest()


def sources_hash(paths):
    import hashlib
    h = hashlib.sha256()
    for rel in paths:
        path = os.path.join(REPO, rel)
        if os.path.exists(path):
            h.update(rel.encode() + b"\0" + open(path, "rb").read())
    return h.hexdigest()[:16]


def pixels_hash(vtk, np, path):
    """sha256 of a PNG's decoded pixels and shape (the encoder's bytes may change, they may not)."""
    import hashlib
    from vtk.util import numpy_support
    r = vtk.vtkPNGReader()
    r.SetFileName(path)
    r.Update()
    img = r.GetOutput()
    a = np.ascontiguousarray(numpy_support.vtk_to_numpy(img.GetPointData().GetScalars()))
    h = hashlib.sha256(repr((img.GetDimensions(), a.shape, str(a.dtype))).encode())
    h.update(a.tobytes())
    return h.hexdigest()[:16]


class ReferenceCache:
    """Reference frames on disk in OUT/refcache, named by a hash of everything that determines
    them: the scan's bytes, dims, type, spacing, the TF file, view, fov, size, shading, the step
    (or the convergence settings) and the model (a probe's pixels and the halving loop's
    sources). Reruns reuse them."""

    def __init__(self, args, vtk, np):
        self.args = args
        self.vtk, self.np = vtk, np
        self.folder = os.path.join(args.out, "refcache")
        os.makedirs(os.path.join(self.folder, "probes"), exist_ok=True)
        self.convergence = sources_hash(CONVERGENCE_SOURCES)
        self.scan_ids = {}
        self.probes = {}

    def model(self, store, scan, tf, view, shade):
        """The probe's pixel hash for this scan/preset/view/shading, drawn once per run."""
        key = (scan, tf, view["text"], shade)
        if key not in self.probes:
            png = os.path.join(self.folder, "probes",
                               f"probe_{scan}_{tf}_{view['name']}_{int(shade)}.png")
            brickcast_render(self.args, store, png, tf, view, PROBE_SIZE, 1.0,
                             ["--reference"] + ([] if shade else ["--no-shading"]))
            self.probes[key] = pixels_hash(self.vtk, self.np, png) + ":" + self.convergence
        return self.probes[key]

    def _key(self, store, scan, tf, view, size, shade, what):
        import hashlib
        spec = SCANS[scan]
        if scan not in self.scan_ids:
            self.scan_ids[scan] = sha256_of(raw_path(self.args, scan))
        tf_path = os.path.join(REPO, "configs", "tf", tf + ".json")
        key = {"scan": self.scan_ids[scan], "dims": spec["dims"], "type": spec["type"],
               "spacing": spec["spacing"], "tf": sha256_of(tf_path), "view": view["text"],
               "fov": self.args.fov, "size": size, "shade": shade,
               "model": self.model(store, scan, tf, view, shade), **what}
        if getattr(self.args, "blend", "composite") != "composite":  # composite keys unchanged
            key["blend"] = self.args.blend
        digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:20]
        return key, digest

    def same_step(self, store, scan, tf, view, size, shade, step):
        key, digest = self._key(store, scan, tf, view, size, shade, {"step": step})
        png = os.path.join(self.folder, f"ref_{scan}_{tf}_{size}_{digest}.png")
        if not os.path.exists(png):
            brickcast_render(self.args, store, png, tf, view, size, step,
                             ["--reference"] + ([] if shade else ["--no-shading"]))
        return png

    def converged(self, store, scan, tf, view, size, shade):
        a = self.args
        key, digest = self._key(store, scan, tf, view, size, shade,
                                {"tolerance": a.conv_tol, "start": a.conv_start,
                                 "floor": a.conv_floor})
        png = os.path.join(self.folder, f"conv_{scan}_{tf}_{size}_{digest}.png")
        stats_path = png[:-4] + ".json"
        if os.path.exists(png) and os.path.exists(stats_path):
            with open(stats_path) as f:
                cached = json.load(f)
            c = cached["convergence"]
            limit = c["timeLimitMs"] / 1e3
            if c["converged"] or c["stop"] == "floor step" or (
                    limit and (not a.conv_time_s or a.conv_time_s <= limit)):
                return png, c, True
        print(f"[compare_vtk]   converging the reference ({scan} {tf} {view['text']} {size}^2)",
              flush=True)
        stats = brickcast_render(
            a, store, png, tf, view, size, a.conv_start,
            ["--reference", "--converge", "%.17g" % a.conv_tol, "--converge-floor",
             "%.17g" % a.conv_floor, "--converge-time-s", "%g" % a.conv_time_s]
            + ([] if shade else ["--no-shading"]))
        with open(png[:-4] + ".key.json", "w") as f:
            json.dump(key, f, indent=2)
        return png, stats["convergence"], False


# ---- one pair: scan x preset x view x size --------------------------------------------------

def ingest_scan(args, scan):
    spec = SCANS[scan]
    store = os.path.join(args.out, "stores", scan + ".bcs")
    os.makedirs(os.path.dirname(store), exist_ok=True)
    if "source" in spec:
        if not os.path.exists(store):
            print(f"[compare_vtk] ingesting {spec['source']} -> {store}", flush=True)
            run([args.brickcast, "ingest", os.path.join(args.data_dir, spec["source"]), "-o",
                 store, "-q"])
        raw = raw_path(args, scan)
        if not os.path.exists(raw):
            run([args.brickcast, "extract", store, "-o", raw])
        info = json.loads(run([args.brickcast, "info", store, "--json"], nice=False))
        spec["dims"] = tuple(int(d) for d in info["dims"])
        spec["type"] = info["type"]
        spec["spacing"] = tuple(float(v) for v in info["spacing_mm"])
        return store
    if not os.path.exists(store):
        print(f"[compare_vtk] ingesting {spec['file']} -> {store}", flush=True)
        run([args.brickcast, "ingest", os.path.join(args.data_dir, spec["file"]),
             "--dims", ",".join(map(str, spec["dims"])), "--type", spec["type"],
             "--spacing", ",".join("%g" % v for v in spec["spacing"]), "--endian", "little",
             "-o", store, "-q"])
    return store


def errors(np, vtk, png, conv_png, same_png):
    """Linear RGB over black against the converged and the same-step reference (None: no
    same-step reference, e.g. a pre-integrated frame, whose own would cost a float64 render)."""
    img = read_rgb(vtk, np, png)
    return {"vsConverged": metrics(np, img, read_rgb(vtk, np, conv_png)),
            "vsSameStep": metrics(np, img, read_rgb(vtk, np, same_png)) if same_png else None}


def bc_sweep(args, ctx, store, scan, tf, view, size, shade, conv_png):
    """brickcast cpu at every --bc-steps step, and pre-integrated at every --bc-preint-steps
    step: warm median ms and errors."""
    np, vtk, cache = ctx["np"], ctx["vtk"], ctx["cache"]
    out = []
    configs = [(step, False) for step in args.bc_step_list] + \
              [(step, True) for step in args.bc_preint_step_list]
    for step, preint in configs:
        tag = f"s{step:g}" + ("_pi" if preint else "")
        png = os.path.join(args.out, "frames", f"bc_{scan}_{tf}_{view['name']}_{size}_{tag}.png")
        stats = brickcast_render(args, store, png, tf, view, size, step,
                                 ["--renderer", "cpu", "--ert", args.bc_ert,
                                  "--repeat", str(args.warmup + args.frames)]
                                 + ([] if shade else ["--no-shading"])
                                 + (["--preintegrate"] if preint else []))
        same = None if preint else cache.same_step(store, scan, tf, view, size, shade, step)
        out.append({"step": step, "preintegrated": preint,
                    "medianMs": statistics.median(stats["frameMs"][args.warmup:]),
                    "firstMs": stats["frameMs"][0], "timesMs": stats["frameMs"][args.warmup:],
                    "samplesPerPixel": stats["samplesPerPixel"], "samples": stats["samples"],
                    "samplesRaising": stats.get("samplesRaising", 0), "png": png,
                    "sameStepRef": same,
                    **errors(np, vtk, png, conv_png, same)})
    return out


def vtk_fixed_point(args, ctx, scan, tf, tfd, view, size, shade):
    """VTK's fixed-point mapper at --step: first (cold) frame, warm median, the PNG."""
    vtk, np = ctx["vtk"], ctx["np"]
    spec = SCANS[scan]
    if ctx.get("volume_of") != scan:
        ctx["image"] = load_volume(vtk, np, raw_path(args, scan),
                                   spec["dims"], spec["spacing"], True, spec["type"])
        ctx["volume_of"] = scan
    if size not in ctx["scenes"]:
        ctx["scenes"][size] = VtkScene(vtk, size, size)
    scene = ctx["scenes"][size]
    box_max = [d * s for d, s in zip(spec["dims"], spec["spacing"])]
    step_mm = args.step * min(spec["spacing"])
    mapper = make_mapper(vtk, "vtk-cpu", ctx["image"], step_mm, ([0.0] * 3, box_max), args.blend)
    scene.set_volume(mapper, vtk_property(vtk, tfd, args.tf_nodes, shade, min(spec["spacing"])))
    scene.set_camera(orbit_camera(box_max, *view["orbit"][:2],
                                  dist=view["orbit"][2] if len(view["orbit"]) > 2 else 1.0,
                                  fov_deg=args.fov, up=view["up"]))
    first = scene.frame()
    for _ in range(max(0, args.warmup - 1)):
        scene.frame()
    times = [scene.frame() for _ in range(args.frames)]
    png = os.path.join(args.out, "frames", f"vtk_{scan}_{tf}_{view['name']}_{size}.png")
    scene.save_png(png)
    if ctx.get("gl") is None:
        ctx["gl"] = scene.gl_renderer()
    return {"medianMs": statistics.median(times), "firstMs": first, "timesMs": times, "png": png}


def fill_references(args, ctx, scan, tf, view, size):
    """--refs-only: the pair's converged reference and its same-step references, nothing timed."""
    store, cache = ctx["stores"][scan], ctx["cache"]
    tfd = load_tf(os.path.join(REPO, "configs", "tf", tf + ".json"), ctx["stats"][scan])
    shade = tfd["shading"]
    t = time.perf_counter()
    _, conv, cached = cache.converged(store, scan, tf, view, size, shade)
    for step in args.bc_step_list:
        cache.same_step(store, scan, tf, view, size, shade, step)
    print(f"[compare_vtk]   references {'cached' if cached else 'made'} in "
          f"{time.perf_counter() - t:.1f} s (converged: {conv['converged']}, "
          f"stop: {conv['stop']})", flush=True)


def run_pair(args, ctx, scan, tf, view, size):
    store = ctx["stores"][scan]
    np, vtk, cache = ctx["np"], ctx["vtk"], ctx["cache"]
    tfd = load_tf(os.path.join(REPO, "configs", "tf", tf + ".json"), ctx["stats"][scan])
    shade = tfd["shading"]
    t = time.perf_counter()
    conv_png, conv, cached = cache.converged(store, scan, tf, view, size, shade)
    conv_s = time.perf_counter() - t
    same_png = cache.same_step(store, scan, tf, view, size, shade, args.step)
    v = vtk_fixed_point(args, ctx, scan, tf, tfd, view, size, shade)
    v.update(errors(np, vtk, v["png"], conv_png, same_png))
    sweep = bc_sweep(args, ctx, store, scan, tf, view, size, shade, conv_png)
    same = next(b for b in sweep if b["step"] == args.step and not b["preintegrated"])
    target = v["vsConverged"]["rmse"]
    fits = [b for b in sweep if b["vsConverged"]["rmse"] <= target]
    equal = min(fits, key=lambda b: b["medianMs"]) if fits else None
    return {"scan": scan, "tf": tf, "view": view["text"], "size": size, "shading": shade,
            "converged": {"png": conv_png, "cached": cached, "wallS": conv_s, **conv},
            "vtk": v, "bcSweep": sweep, "bcSameStep": same, "bcEqualError": equal,
            "ratioSameStep": same["medianMs"] / v["medianMs"],
            "ratioEqualError": equal["medianMs"] / v["medianMs"] if equal else None}


# ---- main ----------------------------------------------------------------------------------

def parse_args():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--brickcast", default=os.path.join(REPO, "build", "tools", "brickcast"))
    ap.add_argument("--out", default="/tmp/vtkcmp")
    ap.add_argument("--data-dir", default=DEFAULT_DATA_DIR)
    ap.add_argument("--scans", default=",".join(SCANS), help="comma list of " + ", ".join(SCANS))
    ap.add_argument("--tfs", default="",
                    help="comma list of presets for every scan (default: each scan's own)")
    ap.add_argument("--sizes", default="256,512", help="comma list of image edges")
    ap.add_argument("--views", default="30,20;120,-30;210,10/0,0,-1",
                    help="';'-separated AZ,EL[,DIST][/UX,UY,UZ] (brickcast --orbit [--up])")
    ap.add_argument("--step", type=float, default=1.0,
                    help="VTK's step and brickcast's same step (voxels of the smallest spacing)")
    ap.add_argument("--bc-steps", default="1,1.25,1.5,2,2.5,3,4",
                    help="brickcast cpu steps; the fastest whose error against the converged "
                         "image is no worse than VTK's is the equal-error point")
    ap.add_argument("--bc-preint-steps", default="",
                    help="steps (voxels) at which brickcast is also run with --preintegrate for "
                         "the equal-error column, e.g. 1.5,2,3,4 (default none: on the shared "
                         "scans' presets it is slower and less accurate than plain at every "
                         "step; bench/vtk/README.md); a pre-integrated frame has no same-step "
                         "reference (its dB after / is n/a)")
    ap.add_argument("--fov", type=float, default=30.0)
    ap.add_argument("--blend", choices=["composite", "mip", "minip"], default="composite",
                    help="the blend mode of both sides: brickcast --mode, VTK's mapper's "
                         "SetBlendMode (its fixed-point mapper draws composite, MIP and MinIP)")
    ap.add_argument("--frames", type=int, default=10, help="timed frames per renderer and pair")
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--bc-ert", default="0.99", help="brickcast --ert (its default 0.99)")
    ap.add_argument("--tf-nodes", choices=["table", "control"], default="table",
                    help="give VTK brickcast's 4096-entry table or the control points only")
    ap.add_argument("--conv-tol", type=float, default=0.5 / 255.0,
                    help="converged: halving the step changes the image by less (max abs, RGBA)")
    ap.add_argument("--conv-start", type=float, default=1.0)
    ap.add_argument("--conv-floor", type=float, default=1.0 / 64.0,
                    help="finest step tried (RenderOptions accepts >= 0.01)")
    ap.add_argument("--conv-time-s", type=float, default=0.0,
                    help="no halving that would end after this (per reference; 0 = none)")
    ap.add_argument("--refs-only", action="store_true",
                    help="only fill the reference cache (converged and same-step references of "
                         "every pair), time nothing: a later run with the same --out times every "
                         "pair on a quiet machine in one go")
    args = ap.parse_args()
    args.scan_list = [s for s in args.scans.split(",") if s]
    for s in args.scan_list:
        if s not in SCANS:
            ap.error(f"--scans: unknown scan '{s}' (known: {', '.join(SCANS)})")
    args.size_list = [int(v) for v in args.sizes.split(",") if v]
    args.bc_step_list = sorted({float(v) for v in args.bc_steps.split(",") if v} | {args.step})
    args.bc_preint_step_list = sorted({float(v) for v in args.bc_preint_steps.split(",") if v})
    args.view_list = [parse_view(v) for v in args.views.split(";") if v]
    if not (args.conv_tol > 0 and math.isfinite(args.conv_tol)):
        ap.error("--conv-tol must be a finite number > 0")
    return args


def main():
    args = parse_args()
    ensure_environment()
    import numpy as np
    import vtk
    vtk.vtkObject.GlobalWarningDisplayOff()

    args.brickcast = os.path.abspath(args.brickcast)
    if not os.access(args.brickcast, os.X_OK):
        raise SystemExit(f"{args.brickcast}: not an executable (build brickcast first)")
    os.makedirs(os.path.join(args.out, "frames"), exist_ok=True)
    ctx = {"np": np, "vtk": vtk, "cache": ReferenceCache(args, vtk, np), "scenes": {}, "stores": {},
           "stats": {}}
    start = time.perf_counter()
    results = {"machine": {"cpus": os.cpu_count(), "uname": " ".join(os.uname())},
               "vtk": vtk.vtkVersion.GetVTKVersion(), "command": " ".join(sys.argv),
               "args": {k: v for k, v in vars(args).items() if not k.endswith("_list")},
               "pairs": []}
    for scan in args.scan_list:
        store = ingest_scan(args, scan)
        ctx["stores"][scan] = store
        ctx["stats"][scan] = StoreStats(
            json.loads(run([args.brickcast, "info", store, "--json"], nice=False)))
        tfs = [t for t in args.tfs.split(",") if t] or SCANS[scan]["tfs"]
        for size in args.size_list:
            for view in args.view_list:
                for tf in tfs:
                    print(f"[compare_vtk] {scan} {tf} {view['text']} {size}^2", flush=True)
                    if args.refs_only:
                        fill_references(args, ctx, scan, tf, view, size)
                        continue
                    results["pairs"].append(run_pair(args, ctx, scan, tf, view, size))
                    write_results(args, results, ctx, start)
    if args.refs_only:
        print(f"[compare_vtk] references in {args.out}/refcache, "
              f"{(time.perf_counter() - start) / 60:.1f} min")
        return
    table = write_results(args, results, ctx, start)
    print(table)


def write_results(args, results, ctx, start):
    results["glRenderer"] = ctx.get("gl")
    results["wallS"] = time.perf_counter() - start
    with open(os.path.join(args.out, "results.json"), "w") as f:
        json.dump(results, f, indent=2, default=str)
    table = format_tables(results, args)
    with open(os.path.join(args.out, "table.md"), "w") as f:
        f.write(table)
    return table


def fmt(v, spec):
    if v is None:
        return "n/a"
    if isinstance(v, float) and math.isinf(v):
        return "inf"
    return format(v, spec)


def err_text(e):
    """PSNR vs converged / vs same step (dB)."""
    same = fmt(e['vsSameStep']['psnr'], '.1f') if e['vsSameStep'] else "n/a"
    return f"{fmt(e['vsConverged']['psnr'], '.1f')} / {same}"


def format_tables(results, args):
    lines = [f"VTK {results['vtk']} vtkFixedPointVolumeRayCastMapper (step {args.step:g}) against "
             f"brickcast --renderer cpu (--ert {args.bc_ert}), {os.cpu_count()} CPUs; times: "
             f"median of {args.frames} frames after {args.warmup} warm-up. Errors: PSNR dB of "
             f"linear RGB over black, against the converged reference / against the float64 "
             f"reference at the renderer's own step. Equal error: the fastest brickcast "
             f"configuration (steps {args.bc_steps}; pre-integrated, 'pi', at steps "
             f"{args.bc_preint_steps or 'none'}) whose error against the converged reference is "
             f"no worse than VTK's. Ratios: brickcast ms / VTK ms. "
             f"Run took {results['wallS'] / 60:.1f} min.", "",
             "| scan | TF | view | size | VTK ms | VTK dB | bc same step ms | dB | ratio "
             "| bc equal error: step | ms | dB | ratio |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for p in results["pairs"]:
        v, s, e = p["vtk"], p["bcSameStep"], p["bcEqualError"]
        lines.append("| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |".format(
            p["scan"], p["tf"], p["view"], p["size"], fmt(v["medianMs"], ".1f"), err_text(v),
            fmt(s["medianMs"], ".1f"), err_text(s), fmt(p["ratioSameStep"], ".2f") + "x",
            (fmt(e["step"], "g") + (" pi" if e["preintegrated"] else "")) if e else "none",
            fmt(e["medianMs"], ".1f") if e else "n/a",
            err_text(e) if e else "n/a",
            fmt(p["ratioEqualError"], ".2f") + "x" if e else "n/a"))
    if args.blend in ("mip", "minip"):
        word = "raised its maximum" if args.blend == "mip" else "lowered its minimum"
        lines += ["", f"brickcast's samples at the same step: taken, and those that {word} "
                  "(the samples that made the image); taken / raising is the march's overhead.",
                  "", "| scan | TF | view | size | samples taken | raising | taken / raising |",
                  "|---|---|---|---:|---:|---:|---:|"]
        for p in results["pairs"]:
            s = p["bcSameStep"]
            lines.append("| {} | {} | {} | {} | {} | {} | {} |".format(
                p["scan"], p["tf"], p["view"], p["size"], s["samples"], s["samplesRaising"],
                fmt(s["samples"] / s["samplesRaising"], ".1f") if s["samplesRaising"] else "n/a"))
    lines += ["", "Converged references (max abs RGBA difference between successive halvings; "
              f"tolerance {args.conv_tol * 255:.2f}/255):", "",
              "| scan | TF | view | size | converged | step (image at) | differences /255 "
              "| seconds per frame |", "|---|---|---|---:|---|---:|---|---|"]
    for p in results["pairs"]:
        c = p["converged"]
        lines.append("| {} | {} | {} | {} | {} | {:g} ({:g}) | {} | {} |".format(
            p["scan"], p["tf"], p["view"], p["size"],
            "yes" if c["converged"] else "NO (" + c["stop"] + ")", c["stepVoxels"],
            c["imageStepVoxels"],
            ", ".join("%.2f" % (s["maxAbsToPrevious"] * 255) for s in c["steps"][1:]),
            ", ".join("%.1f" % (s["renderMs"] / 1e3) for s in c["steps"])))
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
