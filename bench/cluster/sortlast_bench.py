#!/usr/bin/env python3
"""Sort-last over MPI ranks: per-rank render time, compositing time and bytes moved
against ranks and image size, beside one process drawing the same frame.

For every --ranks count and --sizes edge it runs `mpirun -np N brickcast render --mpi
--mpi-barrier --repeat F` (the barrier makes the compositing time its own: without it a rank's
compositing includes waiting for slower ranks), and `brickcast render --renderer cpu` with the
same threads per process for ranks = 1. Figures are warm medians (the first frame dropped).
Prints a markdown table; --json writes every number.

  bench/cluster/sortlast_bench.py --brickcast build/tools/brickcast --store cthead.bcs \\
      --ranks 1,2,4 --sizes 256,512,1024 --threads 1

On a machine with fewer cores than ranks x threads the ranks share cores (mpirun
--oversubscribe): per-rank render times then measure the sharing, not a node; the compositing
time and the bytes do not depend on it as much. State the machine with the table.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile


def run(cmd):
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if r.returncode != 0:
        sys.exit(f"command failed ({r.returncode}): {' '.join(cmd)}\n{r.stdout}")
    return r.stdout


def warm(values):
    return statistics.median(values[1:] if len(values) > 1 else values)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--brickcast", default="build/tools/brickcast")
    ap.add_argument("--mpirun", default="mpirun")
    ap.add_argument("--store", required=True)
    ap.add_argument("--ranks", default="1,2,4")
    ap.add_argument("--sizes", default="256,512,1024")
    ap.add_argument("--threads", type=int, default=1, help="CPU threads per rank")
    ap.add_argument("--frames", type=int, default=6, help="frames per run (the first is dropped)")
    ap.add_argument("--render-args", default="--tf ct-bone --orbit 30,20",
                    help="passed to every brickcast render")
    ap.add_argument("--json", help="write every number here")
    a = ap.parse_args()
    ranks = [int(v) for v in a.ranks.split(",") if v]
    sizes = [int(v) for v in a.sizes.split(",") if v]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        png, stats = os.path.join(tmp, "f.png"), os.path.join(tmp, "s.json")
        for size in sizes:
            for n in ranks:
                common = ["render", a.store, "-o", png, "--size", f"{size},{size}", "--stats",
                          stats, "--repeat", str(a.frames), "--threads", str(a.threads)]
                common += a.render_args.split()
                if n == 1:
                    run([a.brickcast] + common + ["--renderer", "cpu"])
                    with open(stats) as f:
                        s = json.load(f)
                    frame = warm(s["frameMs"])
                    rows.append({"ranks": 1, "size": size, "frameMs": frame, "renderMax": frame,
                                 "renderMean": frame, "imbalance": 1.0, "compositeMs": 0.0,
                                 "bytes": 0, "samples": s["samples"]})
                    continue
                run([a.mpirun, "--allow-run-as-root", "--oversubscribe", "-np", str(n),
                     a.brickcast] + common + ["--mpi", "--mpi-barrier"])
                with open(stats) as f:
                    s = json.load(f)
                rows.append({"ranks": n, "size": size, "frameMs": warm(s["frameMs"]),
                             "renderMax": s["renderMsMax"], "renderMean": s["renderMsMean"],
                             "imbalance": s["imbalance"],
                             "compositeMs": warm(s["compositeMsFrames"]),
                             "bytes": s["bytesComposited"], "samples": s["samples"],
                             "perRank": s["perRank"]})
    print(f"| ranks | size | frame ms | render ms max / mean | imbalance | composite ms "
          f"| bytes moved | bytes / pixel | samples |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['ranks']} | {r['size']}² | {r['frameMs']:.1f} | {r['renderMax']:.1f} / "
              f"{r['renderMean']:.1f} | {r['imbalance']:.2f} | {r['compositeMs']:.1f} "
              f"| {r['bytes'] / 2**20:.2f} MiB | {r['bytes'] / r['size']**2:.1f} "
              f"| {r['samples']} |")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"args": vars(a), "rows": rows}, f, indent=2)


if __name__ == "__main__":
    main()
