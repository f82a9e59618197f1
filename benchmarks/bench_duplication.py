"""The duplication budget: references a triangle, SAH cost and build time with and without it.

Usage: .venv/bin/python benchmarks/bench_duplication.py [--cards 50000] [--runs 3] [--unbounded-cards 20000]

Scenes where the SAH alone splits on and on (flat, densely overlapping triangles: cards 0.05 wide
scattered over a unit square in z = 0, and a 20,000-triangle fan in z = 0, beside the same fan
tilted out of the plane), and ordinary ones where the budget should change nothing (suzanne-251k,
soup-100k, a 180k wavy grid, the same grid flat, a dense 100k soup). Each is built with the default
budget (16) and without one (None; the cards at `--unbounded-cards`, as 50,000 of them took 3.5 GB
and 36 s unbounded). Printed: references a triangle, SAH cost, leaves, median build time. Compile
time is paid first on a small scene and printed on its own line.
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core  # noqa: E402
import results  # noqa: E402
from scenes import load_scene  # noqa: E402


def cards(n, seed=0):
    """n triangles ~0.05 across over the unit square, all in z = 0."""
    rng = np.random.default_rng(seed)
    return ((rng.random((n, 1, 3)) + 0.05 * rng.standard_normal((n, 3, 3))) * [1, 1, 0]).astype(np.float32)


def fan(n=20000, tilted=False):
    """A disk cap of n triangles sharing the centre vertex, in z = 0 or turned by a random rotation."""
    a = np.linspace(0.0, 2 * np.pi, n + 1)
    ring = np.c_[np.cos(a), np.sin(a), np.zeros(n + 1)]
    tris = np.stack([np.zeros((n, 3)), ring[:-1], ring[1:]], 1)
    if tilted:
        tris = tris @ np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))[0].T
    return tris.astype(np.float32)


def grid(n=300, flat=False):
    """A 2(n-1)^2-triangle height field over 10 x 10 (wavy, or flat in z = 0)."""
    x, y = np.meshgrid(np.linspace(0, 10, n), np.linspace(0, 10, n))
    z = np.zeros_like(x) if flat else 0.3 * np.sin(x * 3) * np.cos(y * 2)
    v = np.stack([x, y, z], -1)
    a, b, c, d = v[:-1, :-1], v[1:, :-1], v[1:, 1:], v[:-1, 1:]
    return np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 3),
                           np.stack([a, c, d], -2).reshape(-1, 3, 3)]).astype(np.float32)


def dense_soup(n=100000, seed=1):
    rng = np.random.default_rng(seed)
    return (rng.random((n, 1, 3)) * 2 + 0.05 * rng.standard_normal((n, 3, 3))).astype(np.float32)


def measure(tris, runs, **options):
    """(references a triangle, SAH cost, leaves, median build ms, every build's ms)."""
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        tree = core.build_kdtree(tris, **options)
        times.append(time.perf_counter() - t)
    s = tree.stats()
    return (s["references"] / len(tris), s["sah_cost"], s["leaves"], 1e3 * float(np.median(times)),
            [1e3 * t for t in times])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cards", type=int, default=50000)
    parser.add_argument("--unbounded-cards", type=int, default=20000)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--out", default=str(results.OUT_DIR), help="folder of bench_duplication.json")
    args = parser.parse_args(argv)
    t = time.perf_counter()
    core.build_kdtree(cards(500))
    jit_seconds = time.perf_counter() - t
    print(f"compile (first build): {jit_seconds:.1f} s")
    rows = []
    scenes = [(f"cards-{args.cards // 1000}k, z = 0", cards(args.cards), cards(args.unbounded_cards)),
              ("fan-20k, z = 0", fan(), None), ("fan-20k, tilted", fan(tilted=True), None),
              ("suzanne-251k", load_scene("suzanne-251k").triangles, None),
              ("soup-100k", load_scene("soup-100k").triangles, None),
              ("wavy grid 180k", grid(), None), ("flat grid 180k", grid(flat=True), None),
              ("dense soup 100k", dense_soup(), None)]
    print(f"{'scene':22s} {'budget':>6s} {'refs/tri':>9s} {'SAH cost':>9s} {'leaves':>9s} {'build ms':>9s}")
    for name, tris, unbounded_tris in scenes:
        for budget in (16.0, None):
            label = name
            if budget is None and unbounded_tris is not None:
                tris, label = unbounded_tris, name.replace(f"{args.cards // 1000}k", f"{args.unbounded_cards // 1000}k")
            per_triangle, sah, leaves, ms, all_ms = measure(tris, args.runs, duplication_budget=budget)
            print(f"{label:22s} {str(budget):>6s} {per_triangle:9.2f} {sah:9.3f} {leaves:9,d} {ms:9.0f}", flush=True)
            rows.append({"scene": label, "triangles": len(tris), "budget": budget,
                         "references_per_triangle": per_triangle, "sah_cost": sah, "leaves": int(leaves),
                         "build_ms": results.figure(all_ms, unit="ms")})
    results.write("bench_duplication", {"runs": args.runs, "rows": rows}, jit_seconds, out_dir=args.out)


if __name__ == "__main__":
    main()
