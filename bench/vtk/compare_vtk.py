#!/usr/bin/env python3
"""brickcast against VTK: time and error against brickcast's float64 reference renderer.

What it does
  1. Loads stanford_cthead (256x256x113 uint16, spacing 1,1,2 mm) into vtkImageData, and
     ingests the same raw file into a brickcast store (`brickcast ingest`, cached in --out).
  2. Rebuilds brickcast's camera (Camera::orbit + ViewBasis), transfer functions
     (configs/tf/*.json placed exactly as render/TransferFunction.cpp places them, from the
     store's own histogram, and sampled into brickcast's 4096-entry table) and optical model
     (render/OPTICS.md: per-unit-step opacity, headlight Blinn-Phong ambient 0.3, diffuse 0.7,
     specular 0.25, shininess 24, black background, trilinear) in VTK for the presets
     ct-bone and ct-skin.
  3. Times VTK's CPU raycaster (vtkFixedPointVolumeRayCastMapper) and GPU raycaster
     (vtkOpenGLGPUVolumeRayCastMapper, i.e. llvmpipe on a GPU-less machine): 2 warm-up frames,
     then the median of N frames of the same view (render + framebuffer read-back), and the
     first (cold) frame on its own.
  4. Renders the brickcast float64 reference (`brickcast render --reference`) of each view, and
     times brickcast's CPU and GPU raycasters (`--renderer cpu|gpu`) the way VTK is timed: one
     invocation draws the view --warmup + --frames times with one renderer (`--repeat`), the
     median of the --stats JSON's frameMs after the warm-up frames is the figure and the first
     frame is the cold one (brick loads/uploads, octree build); process start-up is not counted.
  5. Compares every image with the reference: linear [0,1] RGB, all pixels, 8-bit PNGs on
     both sides. brickcast writes premultiplied RGBA (RGB already composited over black); VTK
     renders over a black background, so both RGB triples are "over black" and alpha is
     ignored. Prints PSNR, max abs difference and RMSE (and brickcast compare's SSIM) as a
     markdown table, writes it to OUT/table.md and everything to OUT/results.json.
  6. With --diagnostics (default on) it also renders the variants that isolate the parts of
     VTK's model that cannot be matched (unshaded, no edge padding, TF control points only),
     so the report can say how much each mismatch alone costs.

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
DEFAULT_DATA = os.path.normpath(
    os.path.join(REPO, "..", "shared", "data", "stanford_cthead_256x256x113_uint16.raw"))

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
            "domain": (dmin, dmax)}


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

def load_volume(vtk, np, path, dims, spacing, pad):
    from vtk.util import numpy_support
    nx, ny, nz = dims
    data = np.fromfile(path, dtype="<u2")
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
    arr = numpy_support.numpy_to_vtk(vol.ravel(), deep=True, array_type=vtk.VTK_UNSIGNED_SHORT)
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


def make_mapper(vtk, kind, image, step_mm, crop_box):
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
    m.SetBlendModeToComposite()
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


def brickcast_render(args, store, out_png, tf, view, extra, step=None):
    stats_path = out_png[:-4] + ".json"
    cmd = [args.brickcast, "render", store, "-o", out_png, "--tf", tf,
           "--orbit", ",".join("%g" % v for v in view["orbit"]),
           "--size", f"{args.size},{args.size}",
           "--step", "%g" % (args.step if step is None else step),
           "--fov", "%g" % args.fov, "--stats", stats_path] + extra
    if view["up"]:
        cmd += ["--up", ",".join("%g" % u for u in view["up"])]
    t = time.perf_counter()
    run(cmd)
    wall = (time.perf_counter() - t) * 1e3
    with open(stats_path) as f:
        stats = json.load(f)
    stats["wallMs"] = wall
    return stats


def brickcast_compare(args, a, b):
    try:
        out = run([args.brickcast, "compare", a, b, "--json"], nice=False)
        return json.loads(out)
    except (SystemExit, ValueError):
        return None


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


# ---- main ----------------------------------------------------------------------------------

def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--brickcast", default=os.path.join(REPO, "build", "tools", "brickcast"))
    ap.add_argument("--out", default="/tmp/vtkcmp")
    ap.add_argument("--data", default=DEFAULT_DATA)
    ap.add_argument("--dims", default="256,256,113")
    ap.add_argument("--spacing", default="1,1,2")
    ap.add_argument("--tfs", default="ct-bone,ct-skin")
    ap.add_argument("--views", default="30,20;210,10/0,0,-1",
                    help="';'-separated AZ,EL[,DIST][/UX,UY,UZ] (brickcast --orbit [--up])")
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--step", type=float, default=1.0, help="voxels of the smallest spacing")
    ap.add_argument("--fov", type=float, default=30.0)
    ap.add_argument("--frames", type=int, default=10, help="timed VTK frames per view")
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--bc-reps", type=int, default=1,
                    help="brickcast invocations per renderer (each draws --warmup + --frames frames)")
    ap.add_argument("--bc-ert", default="0.99", help="brickcast --ert (its default 0.99)")
    ap.add_argument("--bc-steps", default="",
                    help="also run brickcast's raycasters at these coarser steps (comma list), "
                         "still against the reference at --step: the equal-error points")
    ap.add_argument("--orbit-azimuths", default="",
                    help="also time an orbit at these azimuths (comma list), first view's EL")
    ap.add_argument("--renderers", default="vtk-cpu,vtk-gpu,bc-cpu,bc-gpu")
    ap.add_argument("--tf-nodes", choices=["table", "control"], default="table",
                    help="give VTK brickcast's 4096-entry table or the control points only")
    ap.add_argument("--no-pad", action="store_true",
                    help="no edge padding + cropping (VTK samples only between voxel centres)")
    ap.add_argument("--diagnostics", dest="diagnostics", action="store_true", default=True)
    ap.add_argument("--no-diagnostics", dest="diagnostics", action="store_false")
    args = ap.parse_args()

    ensure_environment()
    import numpy as np
    import vtk
    vtk.vtkObject.GlobalWarningDisplayOff()

    args.brickcast = os.path.abspath(args.brickcast)
    if not os.access(args.brickcast, os.X_OK):
        raise SystemExit(f"{args.brickcast}: not an executable (build brickcast first)")
    os.makedirs(args.out, exist_ok=True)
    dims = [int(v) for v in args.dims.split(",")]
    spacing = [float(v) for v in args.spacing.split(",")]
    box_max = [d * s for d, s in zip(dims, spacing)]
    step_mm = args.step * min(spacing)
    unit_distance = min(spacing)  # TF alpha is per voxel of the smallest spacing
    views = [parse_view(v) for v in args.views.split(";") if v]
    tfs = [t for t in args.tfs.split(",") if t]
    renderers = [r for r in args.renderers.split(",") if r]

    store = os.path.join(args.out, "cthead.bcs")
    if not os.path.exists(store):
        print(f"[compare_vtk] ingesting {args.data} -> {store}", flush=True)
        run([args.brickcast, "ingest", args.data, "--dims", args.dims, "--type", "u16",
             "--spacing", args.spacing, "--endian", "little", "-o", store])
    info = json.loads(run([args.brickcast, "info", store, "--json"], nice=False))
    stats = StoreStats(info)

    pad = not args.no_pad
    image = load_volume(vtk, np, args.data, dims, spacing, pad)
    crop = ([0.0, 0.0, 0.0], box_max) if pad else None
    scene = VtkScene(vtk, args.size, args.size)
    results = {"machine": {"cpus": os.cpu_count(), "uname": " ".join(os.uname())},
               "vtk": vtk.vtkVersion.GetVTKVersion(), "display": os.environ.get("DISPLAY"),
               "xvfb": os.environ.get("BC_VTK_REEXEC_X") == "1",
               "args": vars(args), "rows": [], "diagnostics": [], "orbit": []}
    gl = None

    def vtk_render(kind, tfd, view, shade=True, nodes=None, use_pad=None, timed=True,
                   png=None, light_ambient=1.0):
        nonlocal gl
        scene.light.SetAmbientColor(light_ambient, light_ambient, light_ambient)
        use_pad = pad if use_pad is None else use_pad
        img = image if use_pad == pad else load_volume(vtk, np, args.data, dims, spacing,
                                                       use_pad)
        mapper = make_mapper(vtk, kind, img, step_mm, ([0.0] * 3, box_max) if use_pad else None)
        prop = vtk_property(vtk, tfd, nodes or args.tf_nodes, shade, unit_distance)
        scene.set_volume(mapper, prop)
        cam = orbit_camera(box_max, *view["orbit"][:2],
                           dist=view["orbit"][2] if len(view["orbit"]) > 2 else 1.0,
                           fov_deg=args.fov, up=view["up"])
        scene.set_camera(cam)
        first = scene.frame()
        if gl is None:
            gl = scene.gl_renderer()
        times = []
        if timed:
            for _ in range(max(0, args.warmup - 1)):
                scene.frame()
            times = [scene.frame() for _ in range(args.frames)]
        if png:
            scene.save_png(png)
        return first, times

    def row(renderer, tf, view, png, ref_png, ms, extra):
        m = metrics(np, read_rgb(vtk, np, png), read_rgb(vtk, np, ref_png))
        cmp = brickcast_compare(args, png, ref_png)
        r = {"renderer": renderer, "tf": tf, "view": view["text"], "png": png,
             "medianMs": ms, **m, "ssim": (cmp or {}).get("ssim")}
        r.update(extra)
        return r

    for view in views:
        for tf in tfs:
            tfd = load_tf(os.path.join(REPO, "configs", "tf", tf + ".json"), stats)
            tag = f"{tf}_{view['name']}"
            ref_png = os.path.join(args.out, f"ref_{tag}.png")
            print(f"[compare_vtk] {tag}: reference", flush=True)
            ref = brickcast_render(args, store, ref_png, tf, view, ["--reference"])
            results["rows"].append({"renderer": "brickcast reference (float64)", "tf": tf,
                                    "view": view["text"], "png": ref_png,
                                    "medianMs": ref["totalMs"], "psnr": float("inf"),
                                    "maxAbs": 0.0, "rmse": 0.0, "ssim": 1.0})
            for kind in renderers:
                print(f"[compare_vtk] {tag}: {kind}", flush=True)
                png = os.path.join(args.out, f"{kind}_{tag}.png")
                if kind.startswith("vtk-"):
                    first, times = vtk_render(kind, tfd, view, png=png)
                    results["rows"].append(row(
                        kind, tf, view, png, ref_png, statistics.median(times),
                        {"firstMs": first, "timesMs": times,
                         "label": ("VTK vtkFixedPointVolumeRayCastMapper" if kind == "vtk-cpu"
                                   else f"VTK vtkOpenGLGPUVolumeRayCastMapper ({gl})")}))
                else:
                    which = kind.split("-")[1]
                    steps = [None] + [float(v) for v in args.bc_steps.split(",") if v]
                    for step in steps:
                        p = png if step is None else png[:-4] + f"_step{step:g}.png"
                        runs = [brickcast_render(args, store, p, tf, view,
                                                 ["--renderer", which, "--ert", args.bc_ert,
                                                  "--repeat", str(args.warmup + args.frames)],
                                                 step=step)
                                for _ in range(args.bc_reps)]
                        warm = [t for r in runs for t in r["frameMs"][args.warmup:]]
                        results["rows"].append(row(
                            kind if step is None else f"{kind}@step{step:g}", tf, view, p,
                            ref_png, statistics.median(warm),
                            {"firstMs": statistics.median(r["frameMs"][0] for r in runs),
                             "renderMs": statistics.median(r["renderMs"] for r in runs),
                             "uploadMs": statistics.median(r["uploadMs"] for r in runs),
                             "wallMs": statistics.median(r["wallMs"] for r in runs),
                             "timesMs": warm,
                             "step": args.step if step is None else step,
                             "samplesPerPixel": runs[0]["samplesPerPixel"],
                             "label": f"brickcast {runs[0]['renderer']}"}))

    if args.diagnostics and views and tfs:
        view = views[0]
        for tf in tfs:
            tfd = load_tf(os.path.join(REPO, "configs", "tf", tf + ".json"), stats)
            tag = f"{tf}_{view['name']}"
            ref_png = os.path.join(args.out, f"ref_{tag}.png")
            ref_ns = os.path.join(args.out, f"ref_noshade_{tag}.png")
            print(f"[compare_vtk] diagnostics {tag}", flush=True)
            brickcast_render(args, store, ref_ns, tf, view, ["--reference", "--no-shading"])
            bc_ns = os.path.join(args.out, f"bc-cpu_noshade_{tag}.png")
            brickcast_render(args, store, bc_ns, tf, view,
                             ["--renderer", "cpu", "--ert", args.bc_ert, "--no-shading"])
            results["diagnostics"].append(row("bc-cpu", tf, view, bc_ns, ref_ns, None,
                                              {"variant": "unshaded (both sides)"}))
            for kind in [k for k in renderers if k.startswith("vtk-")]:
                variants = [("unshaded (both sides)", dict(shade=False), ref_ns),
                            ("no edge pad/crop" if pad else "edge pad + crop",
                             dict(use_pad=not pad), ref_png),
                            ("TF control points only" if args.tf_nodes == "table"
                             else "TF 4096-entry table",
                             dict(nodes="control" if args.tf_nodes == "table" else "table"),
                             ref_png),
                            ("VTK default light (black ambient colour)",
                             dict(light_ambient=0.0), ref_png)]
                for name, kw, rp in variants:
                    short = name.split()[0] + ("_" + name.split()[1] if " " in name else "")
                    png = os.path.join(args.out, f"{kind}_diag_{short}_{tag}.png")
                    vtk_render(kind, tfd, view, timed=False, png=png, **kw)
                    results["diagnostics"].append(row(kind, tf, view, png, rp, None,
                                                      {"variant": name}))

    if args.orbit_azimuths:
        view = views[0]
        azs = [float(a) for a in args.orbit_azimuths.split(",")]
        for tf in tfs:
            tfd = load_tf(os.path.join(REPO, "configs", "tf", tf + ".json"), stats)
            for kind in renderers:
                times = []
                for az in azs:
                    v = dict(view, orbit=[az] + view["orbit"][1:])
                    if kind.startswith("vtk-"):
                        times.append(statistics.median(vtk_render(kind, tfd, v)[1]))
                    else:
                        png = os.path.join(args.out, f"orbit_{kind}_{tf}.png")
                        frames = brickcast_render(
                            args, store, png, tf, v,
                            ["--renderer", kind.split("-")[1], "--ert", args.bc_ert,
                             "--repeat", str(args.warmup + args.frames)])["frameMs"]
                        times.append(statistics.median(frames[args.warmup:]))
                results["orbit"].append({"renderer": kind, "tf": tf, "azimuths": azs,
                                         "msPerAzimuth": times,
                                         "medianMs": statistics.median(times)})

    results["glRenderer"] = gl
    with open(os.path.join(args.out, "results.json"), "w") as f:
        json.dump(results, f, indent=2, default=str)
    table = format_tables(results, args)
    with open(os.path.join(args.out, "table.md"), "w") as f:
        f.write(table)
    print(table)


def fmt(v, spec):
    if v is None:
        return "n/a"
    if isinstance(v, float) and math.isinf(v):
        return "inf"
    return format(v, spec)


def format_tables(results, args):
    lines = [f"VTK {results['vtk']} (OpenGL: {results.get('glRenderer')}; "
             f"{'Xvfb' if results['xvfb'] else 'DISPLAY ' + str(results['display'])}), "
             f"{os.cpu_count()} CPUs, {args.size}x{args.size}, step {args.step:g} voxel, shaded. "
             f"VTK: median of {args.frames} frames after {args.warmup} warm-up (first = cold "
             f"frame); brickcast the same (`render --repeat`, --stats frameMs; renderMs = the "
             f"last frame's march only), x{args.bc_reps} invocations, --ert {args.bc_ert}. Errors: "
             f"linear RGB over black against the float64 reference of the same view.", "",
             "| renderer | view | TF | median ms | first/cold ms | renderMs | PSNR dB vs reference "
             "| max abs | RMSE | SSIM |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    names = {"vtk-cpu": "VTK FixedPoint (CPU)", "vtk-gpu": "VTK GPU mapper (llvmpipe)",
             "bc-cpu": "brickcast --renderer cpu", "bc-gpu": "brickcast --renderer gpu (llvmpipe)",
             "brickcast reference (float64)": "brickcast --reference (float64)"}
    def name_of(key):
        base, _, step = key.partition("@step")
        return names.get(base, base) + (f" --step {step}" if step else "")

    for r in results["rows"]:
        lines.append("| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |".format(
            name_of(r["renderer"]), r["view"], r["tf"],
            fmt(r["medianMs"], ".1f"), fmt(r.get("firstMs"), ".1f"),
            fmt(r.get("renderMs"), ".1f"), fmt(r["psnr"], ".2f"),
            fmt(r["maxAbs"] * 255.0, ".0f") + "/255", fmt(r["rmse"], ".4f"),
            fmt(r.get("ssim"), ".4f")))
    if results["diagnostics"]:
        lines += ["", "Diagnostics (first view): each variant against the matching reference "
                  "(unshaded variants against `--reference --no-shading`).", "",
                  "| renderer | TF | variant | PSNR dB | max abs | RMSE | mean signed diff |",
                  "|---|---|---|---:|---:|---:|---:|"]
        for r in results["diagnostics"]:
            lines.append("| {} | {} | {} | {} | {} | {} | {} |".format(
                names.get(r["renderer"], r["renderer"]), r["tf"], r["variant"],
                fmt(r["psnr"], ".2f"), fmt(r["maxAbs"] * 255.0, ".0f") + "/255",
                fmt(r["rmse"], ".4f"), fmt(r["meanSigned"], "+.4f")))
    if results["orbit"]:
        lines += ["", "Orbit (first view's elevation, per-azimuth median ms, then the median):", "",
                  "| renderer | TF | azimuths | ms per azimuth | median ms |", "|---|---|---|---|---:|"]
        for o in results["orbit"]:
            lines.append("| {} | {} | {} | {} | {:.1f} |".format(
                names.get(o["renderer"], o["renderer"]), o["tf"],
                ",".join("%g" % a for a in o["azimuths"]),
                ", ".join("%.0f" % t for t in o["msPerAzimuth"]), o["medianMs"]))
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
