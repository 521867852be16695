#!/usr/bin/env python3
"""Condenses the CSV of `bc_bench_render` (build/bench/) into the tables of docs/benchmarks/rendering.md.

usage: scripts/bench_tables.py BENCH.csv [CPU.csv]
A run with --renderer both holds GPU and CPU rows ("... (CPU)") in one file, so the CPU
against llvmpipe ratios are taken in one run; a second file adds CPU rows of another run.
"""
import csv
import sys


def load(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def index(rows):
    out = {}
    for r in rows:
        if r["kind"] == "path":
            out[(r["dataset"], r["tf"], r["path"], r["technique"].replace(" (CPU)", ""))] = r
    return out


def scenes(rows):
    seen = []
    for r in rows:
        key = (r["dataset"], r["tf"])
        if r["kind"] == "path" and key not in seen:
            seen.append(key)
    return seen


def ms(r):
    return float(r["ms"])


def speed(base, r):
    return f"{ms(base) / ms(r):.2f}×"


def psnr(r):
    return r["psnr_db"] if r["psnr_db"] not in ("n/a", "inf") else r["psnr_db"]


def oracle(r):
    v = float(r["samples_over_oracle"])
    return "n/a" if v != v else f"{v:.2f}"


def gpu_table(rows, path):
    ix = index(rows)
    print(f"\n| dataset / TF ({path}) | plain ms | +ERT | +bricks | +octree | +octree +ERT | "
          "+frustums (over +bricks) | all | all ms | spp plain → all | samples ÷ oracle (all) | "
          "PSNR dB no ERT / ERT |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for d, tf in scenes(rows):
        g = lambda t: ix[(d, tf, path, t)]
        p = g("plain")
        print(f"| {d} / {tf} | {ms(p):.0f} | {speed(p, g('+ERT'))} | {speed(p, g('+bricks'))} | "
              f"{speed(p, g('+octree'))} | {speed(p, g('+octree +ERT'))} | "
              f"{speed(g('+bricks'), g('+occlusion frustums'))} | {speed(p, g('all'))} | "
              f"{ms(g('all')):.0f} | {float(p['samples_per_pixel']):.1f} → "
              f"{float(g('all')['samples_per_pixel']):.1f} | {oracle(g('all'))} | "
              f"{psnr(p)} / {psnr(g('+ERT'))} |")


def cpu_table(gpu, cpu):
    gi, ci = index(gpu), index(cpu)
    print("\n| dataset / TF (orbit) | CPU plain ms | CPU +octree +ERT ms | speed-up | GPU (llvmpipe) "
          "+octree +ERT ms | CPU over llvmpipe | PSNR dB (CPU, ERT) |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for d, tf in scenes(cpu):
        p, a = ci[(d, tf, "orbit", "plain")], ci[(d, tf, "orbit", "+octree +ERT")]
        g = gi.get((d, tf, "orbit", "+octree +ERT"))
        print(f"| {d} / {tf} | {ms(p):.0f} | {ms(a):.1f} | {speed(p, a)} | "
              f"{ms(g):.0f} | {ms(g) / ms(a):.1f}× | {psnr(a)} |" if g else
              f"| {d} / {tf} | {ms(p):.0f} | {ms(a):.1f} | {speed(p, a)} | – | – | {psnr(a)} |")


def sweep_table(rows):
    print("\n| dataset / TF | " + " | ".join(f"step {s}" for s in ("0.25", "0.5", "1", "2", "4")) + " |")
    print("|---|---:|---:|---:|---:|---:|")
    by = {}
    for r in rows:
        if r["kind"] == "sweep":
            by.setdefault((r["dataset"], r["tf"]), []).append(r)
    for (d, tf), rs in by.items():
        cells = [f"{ms(r):.0f} ms, {psnr(r)} dB" for r in sorted(rs, key=lambda r: float(r["step"]))]
        print(f"| {d} / {tf} | " + " | ".join(cells) + " |")


def main():
    rows = load(sys.argv[1])
    gpu = [r for r in rows if not r["technique"].endswith(" (CPU)")]
    cpu = [r for r in rows if r["technique"].endswith(" (CPU)")]
    if len(sys.argv) > 2:
        cpu = load(sys.argv[2])
    gpu_table(gpu, "orbit")
    gpu_table(gpu, "jumps")
    sweep_table(gpu)
    if cpu:
        cpu_table(gpu, cpu)


if __name__ == "__main__":
    main()
