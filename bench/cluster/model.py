#!/usr/bin/env python3
"""A model of sort-last frames past this machine: frame time and memory per node for
8 to 1024 nodes and 1 to 100 GB volumes, from the figures sortlast_bench.py measured here.

It is fitted on the 1- and 2-rank rows of a `sortlast_bench.py --json` file and checked against
its 4-rank rows (printed beside the prediction), then extrapolated with a stated network:

  bench/cluster/model.py --bench sortlast.json [--latency-us 2] [--bandwidth-gbs 12.5]

The model (render/SCALEOUT.md has the algorithm it describes):
- Render: a rank draws its part's segment of every ray over its footprint. One process draws
  the frame in T1 (measured per image size); the slowest of N ranks in T1 / N times two
  overheads, each 1 + c log2 N with c fitted on 2 ranks: the imbalance (max / mean render ms:
  the parts hold equal bytes, not equal work for the view) and the samples early termination
  no longer saves across parts (samples at N / samples at 1). A volume of V bytes instead of the
  bench's V0 takes (V / V0)^(1/3) the samples at the same image size and step in voxels (a ray
  crosses the volume's edge), so T1 scales by that.
- Compositing (direct send): the parts' footprints add up to k N^(1/3) image areas (a k-d split
  of a cube: N parts, each seen over N^(-2/3) of the area), 16 bytes a pixel (RGBA float); k is
  fitted on 2 ranks. A rank sends the N - 1 other band owners the pieces of its footprint in
  their bands (the piece in its own band stays: (N - 1) / N of it moves), and every band but
  rank 0's goes to rank 0: bytes moved = 16 P (k N^(1/3) + 1) (N - 1) / N. Time = latency
  (N - 1) + bytes per rank / bandwidth + gamma bytes per rank, gamma the compositing work per
  byte measured here (over loopback, where moving bytes is a memcpy), plus rank 0's gather of
  the bands (16 P bytes / bandwidth).
- Memory per node: the volume's decompressed bricks over N (the parts are balanced by bytes),
  capped by the host budget, plus the frame buffers (16 P bytes, twice).
Nothing here is measured past 4 ranks on 2 cores: the extrapolation is the model's, not a
measurement, and says so.
"""
import argparse
import json
import math
import os
import sys


def fit(rows):
    """Per image size: T1, the 2-rank overhead c, the footprint factor k and gamma."""
    by = {}
    for r in rows:
        by.setdefault(r["size"], {})[r["ranks"]] = r
    out = {}
    for size, rs in sorted(by.items()):
        if 1 not in rs or 2 not in rs:
            sys.exit(f"model: size {size} needs 1- and 2-rank rows")
        t1 = rs[1]["frameMs"]
        p = size * size
        two = rs[2]
        imbalance = max(0.0, two["imbalance"] - 1.0)  # 1 + c log2 2
        extra = max(0.0, two["samples"] / rs[1]["samples"] - 1.0)
        # bytes(2) = 16 P (k 2^(1/3) + 1) / 2
        k = max(0.0, (two["bytes"] / (16.0 * p) * 2.0 - 1.0) / 2 ** (1 / 3))
        gamma = two["compositeMs"] / max(1.0, two["bytes"] / 2)  # ms per byte per rank
        out[size] = {"t1": t1, "imbalance": imbalance, "extra": extra, "k": k, "gamma": gamma,
                     "rows": rs}
    return out


def predict(m, n, size, volume_ratio, latency_ms, bandwidth_bpms, budget_bytes=None,
            volume_bytes=None):
    p = size * size
    t1 = m["t1"] * volume_ratio ** (1 / 3)
    lg = math.log2(n)
    # The imbalance is at most n (one rank with all the work).
    render = t1 / n * min(n, 1 + m["imbalance"] * lg) * (1 + m["extra"] * lg)
    if n == 1:
        return {"render": render, "composite": 0.0, "frame": render, "bytes": 0.0}
    total_bytes = 16.0 * p * (m["k"] * n ** (1 / 3) + 1.0) * (n - 1) / n
    per_rank = total_bytes / n
    composite = (latency_ms * (n - 1) + per_rank / bandwidth_bpms + m["gamma"] * per_rank +
                 16.0 * p / bandwidth_bpms)
    out = {"render": render, "composite": composite, "frame": render + composite,
           "bytes": total_bytes}
    if volume_bytes is not None:
        share = volume_bytes / n
        out["memory"] = (min(share, budget_bytes) if budget_bytes else share) + 32.0 * p
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bench", required=True, help="sortlast_bench.py --json output")
    ap.add_argument("--volume-gb", type=float, default=0.0,
                    help="decompressed bytes of the bench's volume in GB (default: from cthead, "
                         "256x256x113 u16)")
    ap.add_argument("--latency-us", type=float, default=2.0, help="one message (default: "
                    "InfiniBand-class 2 us)")
    ap.add_argument("--bandwidth-gbs", type=float, default=12.5,
                    help="per node, GB/s (default: 100 Gb/s InfiniBand HDR100)")
    ap.add_argument("--host-budget-gb", type=float, default=0.0,
                    help="host brick cache per node (0: the share is held whole)")
    ap.add_argument("--cores", type=int, default=os.cpu_count(),
                    help="cores of the machine the bench ran on: in the check, ranks x threads "
                         "beyond them share cores, which the prediction allows for")
    ap.add_argument("--nodes", default="8,16,64,256,1024")
    ap.add_argument("--volumes-gb", default="1,10,100")
    a = ap.parse_args()
    with open(a.bench) as f:
        bench = json.load(f)
    models = fit(bench["rows"])
    v0 = a.volume_gb * 1e9 if a.volume_gb > 0 else 256 * 256 * 113 * 2
    latency_ms = a.latency_us / 1e3
    bandwidth = a.bandwidth_gbs * 1e9 / 1e3  # bytes per ms
    budget = a.host_budget_gb * 1e9 if a.host_budget_gb > 0 else None

    print("Check: fitted on 1 and 2 ranks, predicted against the measured 4 ranks "
          f"(this machine: loopback, latency and bandwidth taken as free; {a.cores} cores)")
    print("| size | ranks | frame ms | predicted | render ms max | predicted | imbalance | "
          "predicted | samples ÷ 1 rank | predicted | bytes | predicted |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    threads = int(bench["args"].get("threads", 1))
    for size, m in models.items():
        for n, r in sorted(m["rows"].items()):
            if n < 4:
                continue
            q = predict(m, n, size, 1.0, 0.0, float("inf"))
            share = max(1.0, n * threads / a.cores)  # ranks sharing cores run that much slower
            q["render"] *= share
            q["frame"] = q["render"] + q["composite"]
            lg = math.log2(n)
            print(f"| {size}² | {n} | {r['frameMs']:.1f} | {q['frame']:.1f} | "
                  f"{r['renderMax']:.1f} | {q['render']:.1f} | {r['imbalance']:.2f} | "
                  f"{1 + m['imbalance'] * lg:.2f} | "
                  f"{r['samples'] / m['rows'][1]['samples']:.2f} | {1 + m['extra'] * lg:.2f} | "
                  f"{r['bytes'] / 2**20:.2f} MiB | {q['bytes'] / 2**20:.2f} MiB |")
    print()
    print(f"Extrapolated (the model, not a measurement): latency {a.latency_us:g} us, "
          f"{a.bandwidth_gbs:g} GB/s per node, the bench's per-core speed")
    print("| volume | size | nodes | render ms | composite ms | frame ms | bytes moved | "
          "memory per node |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    nodes = [int(v) for v in a.nodes.split(",") if v]
    for vgb in [float(v) for v in a.volumes_gb.split(",") if v]:
        vb = vgb * 1e9
        for size, m in models.items():
            for n in nodes:
                q = predict(m, n, size, vb / v0, latency_ms, bandwidth, budget, vb)
                print(f"| {vgb:g} GB | {size}² | {n} | {q['render']:.1f} | {q['composite']:.2f} "
                      f"| {q['frame']:.1f} | {q['bytes'] / 2**20:.1f} MiB | "
                      f"{q['memory'] / 2**30:.2f} GiB |")


if __name__ == "__main__":
    main()
