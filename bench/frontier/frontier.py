#!/usr/bin/env python3
"""Run time against error: which configuration draws a frame fastest for a given error.

For every scan x preset x view x size (--scans, --tfs, --views, --sizes):
  1. The true image: the converged float64 reference (`brickcast render --reference
     --converge`, render/ConvergedReference.h), cached in OUT/refcache exactly as
     bench/vtk/compare_vtk.py caches it (the same keys and files, so one cache serves both).
  2. Every configuration of --renderers x --steps x pre-integration (off/on) x jitter
     (off/on) draws the frame with `brickcast render --repeat` (--warmup frames, then the
     median of --frames); the GPU raycaster does not pre-integrate, so it has half as many.
  3. Each frame's error against the true image (`brickcast compare --json`, RGBA, linear):
     PSNR, max abs, and the low-pass PSNR (render/ImageMetrics.h: the error after a Gaussian
     low pass of 1.5 pixels, which keeps structured error such as wood-grain rings and lets
     pixel noise average out; the figure a viewer sees).
  4. The frontier: the configurations no other beats on both time and error (one frontier for
     PSNR, one for low-pass PSNR), marked in the tables; per pair, an SVG plot of time against
     PSNR with the frontier drawn (OUT/plots/*.svg).
  5. A summary: for targets of 35, 40 and 45 dB (PSNR and low-pass PSNR), the fastest
     configuration that reaches it per pair, and how often each technique is on the frontier.

Prints markdown tables (also OUT/table.md) and writes every number to OUT/results.json,
rewritten after every pair. Needs only Python's standard library and brickcast.

    python3 bench/frontier/frontier.py --brickcast build/tools/brickcast --out /tmp/frontier
"""

import argparse
import json
import math
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "vtk"))
import compare_vtk as cv  # noqa: E402  (the scans, the stores, the reference cache)


def parse_args():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--brickcast", default=os.path.join(cv.REPO, "build", "tools", "brickcast"))
    ap.add_argument("--out", default="/tmp/frontier")
    ap.add_argument("--data-dir", default=cv.DEFAULT_DATA_DIR)
    ap.add_argument("--scans", default="cthead,headsq,CT_AVM,frog,hydrogen",
                    help="comma list of " + ", ".join(cv.SCANS))
    ap.add_argument("--tfs", default="", help="comma list of presets (default: each scan's own)")
    ap.add_argument("--sizes", default="256")
    ap.add_argument("--views", default="30,20;210,10/0,0,-1",
                    help="';'-separated AZ,EL[,DIST][/UX,UY,UZ]")
    ap.add_argument("--steps", default="0.5,0.75,1,1.5,2,3")
    ap.add_argument("--renderers", default="cpu",
                    help="comma list of cpu, gpu (gpu on a software rasteriser is slow)")
    ap.add_argument("--fov", type=float, default=30.0)
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--conv-tol", type=float, default=0.5 / 255.0)
    ap.add_argument("--conv-start", type=float, default=1.0)
    ap.add_argument("--conv-floor", type=float, default=1.0 / 64.0)
    ap.add_argument("--conv-time-s", type=float, default=0.0)
    ap.add_argument("--tables-from", default="",
                    help="print the tables of an earlier run's results.json and exit")
    args = ap.parse_args()
    args.scan_list = [s for s in args.scans.split(",") if s]
    for s in args.scan_list:
        if s not in cv.SCANS:
            ap.error(f"--scans: unknown scan '{s}' (known: {', '.join(cv.SCANS)})")
    args.size_list = [int(v) for v in args.sizes.split(",") if v]
    args.step_list = sorted({float(v) for v in args.steps.split(",") if v})
    args.view_list = [cv.parse_view(v) for v in args.views.split(";") if v]
    args.renderer_list = [r for r in args.renderers.split(",") if r]
    for r in args.renderer_list:
        if r not in ("cpu", "gpu"):
            ap.error(f"--renderers: '{r}' is not cpu or gpu")
    return args


def configurations(args):
    for renderer in args.renderer_list:
        for step in args.step_list:
            for pre in (False, True):
                if pre and renderer != "cpu":
                    continue  # the GPU raycaster refuses pre-integration
                for jitter in (False, True):
                    yield {"renderer": renderer, "step": step, "pre": pre, "jitter": jitter}


def label(c):
    parts = [c["renderer"], "step %g" % c["step"]]
    if c["pre"]:
        parts.append("pre")
    if c["jitter"]:
        parts.append("jitter")
    return " ".join(parts)


def compare(args, png, ref):
    out = cv.run([args.brickcast, "compare", png, ref, "--json"], nice=False)
    j = json.loads(out)
    inf = float("inf")
    return {"psnr": j["psnrDb"] if j["psnrDb"] is not None else inf,
            "lowPassPsnr": j["lowPassPsnrDb"] if j["lowPassPsnrDb"] is not None else inf,
            "maxAbs255": j["maxAbs255"], "rmse": j["rmse"], "ssim": j["ssim"]}


def frontier(points, key):
    """Indices of the points no other beats on both time (lower) and `key` (higher)."""
    order = sorted(range(len(points)), key=lambda i: (points[i]["medianMs"], -points[i][key]))
    best, on = -float("inf"), set()
    for i in order:
        if points[i][key] > best:
            on.add(i)
            best = points[i][key]
    return on


def run_pair(args, ctx, scan, tf, view, size):
    store = ctx["stores"][scan]
    cache = ctx["cache"]
    tfd = cv.load_tf(os.path.join(cv.REPO, "configs", "tf", tf + ".json"), ctx["stats"][scan])
    shade = tfd["shading"]
    conv_png, conv, cached = cache.converged(store, scan, tf, view, size, shade)
    points = []
    for c in configurations(args):
        name = "%s_%s_%s_%d_%s_s%g%s%s.png" % (scan, tf, view["name"], size, c["renderer"],
                                              c["step"], "_pre" if c["pre"] else "",
                                              "_jit" if c["jitter"] else "")
        png = os.path.join(args.out, "frames", name)
        extra = ["--renderer", c["renderer"], "--repeat", str(args.warmup + args.frames)]
        extra += ["--preintegrate"] if c["pre"] else []
        extra += ["--jitter"] if c["jitter"] else []
        extra += [] if shade else ["--no-shading"]
        stats = cv.brickcast_render(args, store, png, tf, view, size, c["step"], extra)
        times = stats["frameMs"][args.warmup:]
        points.append({**c, "label": label(c), "medianMs": statistics.median(times),
                       "timesMs": times, "samplesPerPixel": stats.get("samplesPerPixel"),
                       "png": png, **compare(args, png, conv_png)})
    on_psnr = frontier(points, "psnr")
    on_low = frontier(points, "lowPassPsnr")
    for i, p in enumerate(points):
        p["frontierPsnr"] = i in on_psnr
        p["frontierLowPass"] = i in on_low
    pair = {"scan": scan, "tf": tf, "view": view["text"], "viewName": view["name"],
            "size": size, "shading": shade,
            "converged": {"png": conv_png, "cached": cached, **conv}, "points": points}
    write_plot(args, pair)
    return pair


# ---- output ---------------------------------------------------------------------------------

COLOURS = {(False, False): "#1f77b4", (False, True): "#2ca02c", (True, False): "#d62728",
           (True, True): "#9467bd"}


def write_plot(args, pair):
    """Time (log) against PSNR: one dot per configuration, the PSNR frontier as a line."""
    pts = pair["points"]
    finite = [p for p in pts if math.isfinite(p["psnr"])]
    if not finite:
        return
    w, h, m = 640, 400, 56
    tmin = min(p["medianMs"] for p in finite) * 0.8
    tmax = max(p["medianMs"] for p in finite) * 1.25
    pmin = math.floor(min(p["psnr"] for p in finite) / 5) * 5
    pmax = math.ceil(max(p["psnr"] for p in finite) / 5) * 5
    pmax += 5 if pmax == pmin else 0

    def x(t):
        return m + (w - 2 * m) * math.log(t / tmin) / math.log(tmax / tmin)

    def y(p):
        return h - m - (h - 2 * m) * (p - pmin) / (pmax - pmin)

    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" '
           f'font-family="sans-serif" font-size="11">',
           f'<rect width="{w}" height="{h}" fill="white"/>',
           f'<text x="{m}" y="20" font-size="13">{pair["scan"]} {pair["tf"]} view '
           f'{pair["view"]} {pair["size"]}&#178;: time against PSNR vs the converged image'
           f'</text>',
           f'<line x1="{m}" y1="{h - m}" x2="{w - m}" y2="{h - m}" stroke="black"/>',
           f'<line x1="{m}" y1="{m}" x2="{m}" y2="{h - m}" stroke="black"/>',
           f'<text x="{w / 2}" y="{h - 16}" text-anchor="middle">ms per frame (log)</text>',
           f'<text x="14" y="{h / 2}" transform="rotate(-90 14 {h / 2})" '
           f'text-anchor="middle">PSNR dB</text>']
    for p in range(int(pmin), int(pmax) + 1, 5):
        out.append(f'<text x="{m - 6}" y="{y(p) + 4}" text-anchor="end">{p}</text>')
    t = 10 ** math.floor(math.log10(tmin))
    while t <= tmax:
        for k in (1, 2, 5):
            if tmin <= t * k <= tmax:
                out.append(f'<text x="{x(t * k)}" y="{h - m + 14}" text-anchor="middle">'
                           f'{t * k:g}</text>')
        t *= 10
    front = sorted((p for p in finite if p["frontierPsnr"]), key=lambda p: p["medianMs"])
    if len(front) > 1:
        path = " ".join(f'{x(p["medianMs"]):.1f},{y(p["psnr"]):.1f}' for p in front)
        out.append(f'<polyline points="{path}" fill="none" stroke="#888" stroke-dasharray="4 3"/>')
    for p in finite:
        colour = COLOURS[(p["pre"], p["jitter"])]
        shape = "circle" if p["renderer"] == "cpu" else "rect"
        cx, cy = x(p["medianMs"]), y(p["psnr"])
        if shape == "circle":
            out.append(f'<circle cx="{cx:.1f}" cy="{cy:.1f}" r="4" fill="{colour}"/>')
        else:
            out.append(f'<rect x="{cx - 4:.1f}" y="{cy - 4:.1f}" width="8" height="8" '
                       f'fill="{colour}"/>')
        if p["frontierPsnr"]:
            out.append(f'<text x="{cx + 6:.1f}" y="{cy - 6:.1f}">{p["label"]}</text>')
    legend = [("plain", (False, False)), ("jitter", (False, True)), ("pre", (True, False)),
              ("pre + jitter", (True, True))]
    for i, (name, key) in enumerate(legend):
        lx = w - m - 110
        ly = m + 14 * i
        out.append(f'<circle cx="{lx}" cy="{ly}" r="4" fill="{COLOURS[key]}"/>')
        out.append(f'<text x="{lx + 8}" y="{ly + 4}">{name}</text>')
    out.append("</svg>")
    os.makedirs(os.path.join(args.out, "plots"), exist_ok=True)
    path = os.path.join(args.out, "plots", "%s_%s_%s_%d.svg" % (
        pair["scan"], pair["tf"], pair["viewName"], pair["size"]))
    with open(path, "w") as f:
        f.write("\n".join(out) + "\n")
    pair["plot"] = path


def fmt_db(v):
    return "inf" if math.isinf(v) else "%.1f" % v


def fastest_reaching(points, key, target):
    fits = [p for p in points if p[key] >= target]
    return min(fits, key=lambda p: p["medianMs"]) if fits else None


TARGETS = {"psnr": (35.0, 40.0, 45.0), "lowPassPsnr": (45.0, 50.0, 55.0)}


def format_tables(results):
    lines = [f"Machine: {results['machine']['cpus']} CPUs, {results['machine']['uname']}",
             f"Command: {results['command']}", ""]
    for pair in results["pairs"]:
        conv = pair["converged"]
        lines.append(f"### {pair['scan']} {pair['tf']}, view {pair['view']}, {pair['size']}², "
                     f"{'shaded' if pair['shading'] else 'unshaded'}; converged at step "
                     f"{conv.get('stepVoxels', 'n/a')} "
                     f"({'converged' if conv.get('converged') else 'NOT converged'})")
        lines.append("")
        lines.append("| configuration | ms | PSNR dB | low-pass PSNR dB | max abs /255 | "
                     "frontier |")
        lines.append("|---|---|---|---|---|---|")
        for p in sorted(pair["points"], key=lambda p: p["medianMs"]):
            marks = ("PSNR " if p["frontierPsnr"] else "") + (
                "low-pass" if p["frontierLowPass"] else "")
            lines.append(f"| {p['label']} | {p['medianMs']:.1f} | {fmt_db(p['psnr'])} | "
                         f"{fmt_db(p['lowPassPsnr'])} | {p['maxAbs255']} | {marks.strip()} |")
        lines.append("")
    lines.append("### Fastest configuration reaching a target (per pair)")
    lines.append("")
    head = "| pair | " + " | ".join(f"PSNR ≥ {t:g}" for t in TARGETS["psnr"]) + " | " + " | ".join(
        f"low-pass ≥ {t:g}" for t in TARGETS["lowPassPsnr"]) + " |"
    lines.append(head)
    lines.append("|---" * (1 + len(TARGETS["psnr"]) + len(TARGETS["lowPassPsnr"])) + "|")
    for pair in results["pairs"]:
        cells = []
        for key in ("psnr", "lowPassPsnr"):
            for t in TARGETS[key]:
                p = fastest_reaching(pair["points"], key, t)
                cells.append(f"{p['label']} ({p['medianMs']:.0f} ms)" if p else "none")
        lines.append(f"| {pair['scan']} {pair['tf']} {pair['view']} {pair['size']}² | "
                     + " | ".join(cells) + " |")
    lines.append("")
    lines.append("### How often each technique is on the frontier")
    lines.append("")
    lines.append("| technique | on the PSNR frontier | on the low-pass frontier | of |")
    lines.append("|---|---|---|---|")
    for name, test in (("jitter", lambda p: p["jitter"]), ("pre-integration", lambda p: p["pre"]),
                       ("plain (neither)", lambda p: not p["jitter"] and not p["pre"])):
        on = sum(1 for pair in results["pairs"] for p in pair["points"]
                 if test(p) and p["frontierPsnr"])
        on_low = sum(1 for pair in results["pairs"] for p in pair["points"]
                     if test(p) and p["frontierLowPass"])
        total = sum(1 for pair in results["pairs"] for p in pair["points"] if test(p))
        lines.append(f"| {name} | {on} | {on_low} | {total} |")
    return "\n".join(lines) + "\n"


def write_results(args, results, start):
    results["wallS"] = time.perf_counter() - start
    with open(os.path.join(args.out, "results.json"), "w") as f:
        json.dump(results, f, indent=2, default=str)
    table = format_tables(results)
    with open(os.path.join(args.out, "table.md"), "w") as f:
        f.write(table)
    return table


def main():
    args = parse_args()
    if args.tables_from:
        with open(args.tables_from) as f:
            print(format_tables(json.load(f)))
        return
    args.brickcast = os.path.abspath(args.brickcast)
    if not os.access(args.brickcast, os.X_OK):
        raise SystemExit(f"{args.brickcast}: not an executable (build brickcast first)")
    os.makedirs(os.path.join(args.out, "frames"), exist_ok=True)
    ctx = {"cache": cv.ReferenceCache(args), "stores": {}, "stats": {}}
    start = time.perf_counter()
    results = {"machine": {"cpus": os.cpu_count(), "uname": " ".join(os.uname())},
               "command": " ".join(sys.argv), "pairs": [],
               "args": {k: v for k, v in vars(args).items() if not k.endswith("_list")}}
    for scan in args.scan_list:
        store = cv.ingest_scan(args, scan)
        ctx["stores"][scan] = store
        ctx["stats"][scan] = cv.StoreStats(
            json.loads(cv.run([args.brickcast, "info", store, "--json"], nice=False)))
        tfs = [t for t in args.tfs.split(",") if t] or cv.SCANS[scan]["tfs"]
        for size in args.size_list:
            for view in args.view_list:
                for tf in tfs:
                    print(f"[frontier] {scan} {tf} {view['text']} {size}^2", flush=True)
                    results["pairs"].append(run_pair(args, ctx, scan, tf, view, size))
                    write_results(args, results, start)
    print(write_results(args, results, start))


if __name__ == "__main__":
    main()
