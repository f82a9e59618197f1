"""Render the benchmark tables of README.md and docs/benchmarks.md from the JSON results in benchmarks/out/.

Usage: python benchmarks/report.py            # rewrite the generated blocks in place
       python benchmarks/report.py --check    # exit 1 when a committed block differs from what the JSON gives

Each generated block sits between marker comments, `<!-- NAME:begin -->` and `<!-- NAME:end -->`; the text
between them is replaced, the rest of the file is left alone. Blocks:

- `figures` (README.md): one small table: build, camera and AO rays against Embree, seed 000's setting,
  our time against Cycles' at equal error.
- `first-use` (README.md): the first render's wait in a fresh Blender, cold and warm (bench_first_render).
- `bench_core`, `bench_seed000`, `profile_seed000`, `bench_render` (docs/benchmarks.md): each benchmark's full table.

Every block names the run it comes from (date, CPU, cores, Numba version, command, and whether it was a
--quick run), so no date or host appears in hand-written prose.
"""
import argparse
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT_DIR = ROOT / "benchmarks" / "out"
README = ROOT / "README.md"
BENCH_DOC = ROOT / "docs" / "benchmarks.md"
FILES = ("bench_core", "bench_seed000", "profile_seed000", "bench_render", "bench_sample_packets", "bench_first_render",
         "bench_instances", "bench_big_mesh")
FIGURE_SCENE = "suzanne-251k"


def load(out_dir):
    """{name: parsed JSON} of the result files present in out_dir."""
    data = {}
    for name in FILES:
        path = Path(out_dir) / f"{name}.json"
        if path.is_file():
            data[name] = json.loads(path.read_text())
    return data


def provenance(result):
    """One line naming the run: date, host, software and command."""
    h = result["host"]
    quick = " **Quick run** (a check that the benchmark works, not a final figure)." if result.get("quick") else ""
    cpu = f"{h['cpu']} ({h['cpu_target']})" if h.get("cpu_target") else h["cpu"]
    return (f"_{result['benchmark']}: {result['date']}, {cpu}, {h['cores']} cores "
            f"({h['numba_threads']} Numba threads), Python {h['python']}, Numba {h['numba']}; "
            f"JIT compile {result['jit_seconds']:.1f} s, not in any figure; "
            f"`{result['command']}`._{quick}")


def missing(name, command):
    return f"_Not measured yet: run `{command}` (writes benchmarks/out/{name}.json)._"


def table(header, rows):
    lines = ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def ms(value):
    return f"{value:,.0f} ms" if value >= 100 else f"{value:.1f} ms"


def ratio(ours, reference):
    return f"{ours / reference:.2f}x"


def core_scene(data, scene=FIGURE_SCENE):
    return data["bench_core"]["results"]["scenes"].get(scene)


def figures_block(data):
    """The README's table: a few headline figures, each beside its reference from the same run."""
    rows, notes = [], []
    if "bench_core" in data and core_scene(data):
        sc = core_scene(data)
        b = sc["builders"]["binned"]
        emb = sc.get("embree")
        n = data["bench_core"]["results"]["runs"]
        rows.append([f"kd-tree build (binned SAH), {sc['triangles']:,} triangles",
                     f"{ms(b['build_ms']['median'])} (SAH cost {b['sah_cost']:.2f})",
                     f"Embree BVH build {ms(emb['build_ms'])}" if emb else "-"])
        for key, label, rays in (("camera_mrays", "camera rays", sc["camera_rays"]),
                                 ("camera_packets_mrays", "camera rays in packets (the renderer's camera pass)",
                                  sc["camera_rays"]), ("ao_mrays", "AO rays", sc["ao_rays"])):
            if key not in b:
                continue
            ours = b[key]["median"]
            ref = b[key].get("reference")
            rows.append([f"{label}, {sc['threads']} threads ({rays:,} rays)", f"{ours:.2f} Mrays/s",
                         f"Embree, 1 thread: {ref['median']:.2f} Mrays/s ({ratio(ours, ref['median'])})" if ref else "-"])
        notes.append(f"Build and rays: `benchmarks/bench_core.py`, {FIGURE_SCENE}, medians of {n} runs.")
        notes.append(provenance(data["bench_core"]))
    if "bench_seed000" in data:
        r = data["bench_seed000"]["results"]
        c = r["configs"]
        told = c["rays=W*H*2"]["seconds"]
        emb = c[r["reference"]]["seconds"]["median"]
        rows.append([f"seed 000's setting: {r['size'][0]}x{r['size'][1]}, rebuild + camera + 1 shadow ray",
                     f"{told['median']:.3f} s (build told the rays; {c['default build']['seconds']['median']:.3f} s default)",
                     f"Embree, 1 thread: {emb:.3f} s ({ratio(told['median'], emb)})"])
        notes.append(provenance(data["bench_seed000"]))
    if "bench_render" in data:
        r = data["bench_render"]["results"]
        for entry in r["time_ratio_at_equal_rmse"]:
            if entry["cycles_samples"] in (4, 16, 64) and entry.get("cycles_adaptive_threshold") is None:
                rows.append([f"our time / Cycles' at equal AO error, Cycles at {entry['cycles_samples']} spp "
                             f"({r['size']}x{r['size']})",
                             f"raw {entry['ours_raw']}, denoised {entry['ours_denoised']}",
                             f"Cycles: {entry['cycles_seconds']:.2f} s, RMSE {entry['cycles_rmse']:.4f}"])
        notes.append(provenance(data["bench_render"]))
    if "bench_sample_packets" in data:
        r = data["bench_sample_packets"]["results"]
        for name in ("ao", "shadow"):
            f = r["renders"][name]
            what = "AO" if name == "ao" else "shadows of a soft point light and sun"
            rows.append([f"render step in packets, {what}, {r['size']}x{r['size']} at {r['samples']} spp",
                         f"{ms(f['packets_ms'])} ({1 / f['ratio']:.2f}x faster)",
                         f"the same rays one by one: {ms(f['single_ms'])}"])
        notes.append(provenance(data["bench_sample_packets"]))
    if not rows:
        return missing("bench_core", "python benchmarks/bench_core.py")
    return table(["figure", "KD Preview", "reference, same run"], rows) + "\n\n" + "\n".join(
        f"- {note}" for note in notes)


def bench_core_block(data):
    if "bench_core" not in data:
        return missing("bench_core", "python benchmarks/bench_core.py")
    res = data["bench_core"]["results"]
    parts = []
    for name, sc in res["scenes"].items():
        parts.append(f"**{name}**: {sc['triangles']:,} triangles, {sc['camera_rays']:,} camera rays, "
                     f"{sc['ao_rays']:,} AO rays, {sc['threads']} threads; medians of {res['runs']} runs.\n")
        rows = []
        for label, b in sc["builders"].items():
            peak = b.get("peak_bytes_per_triangle")
            rows.append([label, ms(b["build_ms"]["median"]), f"{b['sah_cost']:.2f}", f"{b['nodes']:,}",
                         b["max_depth"], f"{b['references_per_triangle']:.2f}",
                         f"{peak:.0f}" if peak is not None else "-",
                         f"{b['camera_mrays']['median']:.2f}", f"{b['ao_mrays']['median']:.2f}"])
        emb = sc.get("embree")
        if emb:
            rows.append(["Embree (embreex, 1 thread)", ms(emb["build_ms"]), "-", "-", "-", "-", "-",
                         f"{emb['camera_mrays']['median']:.2f}", f"{emb['ao_mrays']['median']:.2f}"])
        bvh = sc.get("bvhtree")
        if bvh and "cam Mrays/s" in bvh:
            rows.append(["Blender BVHTree (Python loop, subset)", ms(bvh["build_ms"]), "-", "-", "-", "-", "-",
                         f"{bvh['cam Mrays/s']:.3f}", f"{bvh['ao Mrays/s']:.3f}"])
        parts.append(table(["builder", "build", "SAH cost", "nodes", "depth", "refs/triangle",
                            "peak B/triangle", "camera Mrays/s", "AO Mrays/s"], rows))
        parts.append("")
    parts.append(provenance(data["bench_core"]))
    return "\n".join(parts)


def bench_seed000_block(data):
    if "bench_seed000" not in data:
        return missing("bench_seed000", "python benchmarks/bench_render.py --only-seed000")
    r = data["bench_seed000"]["results"]
    rows = []
    for name, c in r["configs"].items():
        s = c["seconds"]
        rows.append([name, f"{s['median']:.3f} s", f"{c['build_seconds']['median']:.3f} s", len(s["runs"]),
                     ", ".join(f"{x:.3f}" for x in s["runs"])])
    return (f"{r['scene']}, {r['size'][0]}x{r['size'][1]}, {r['what']} at {tuple(r['light'])}.\n\n"
            + table(["configuration", "time to image (median)", "build (median)", "runs", "every run (s)"], rows)
            + "\n\n" + provenance(data["bench_seed000"]))


def profile_seed000_block(data):
    if "profile_seed000" not in data:
        return missing("profile_seed000", "python benchmarks/profile_seed000.py")
    r = data["profile_seed000"]["results"]
    configs = list(r["ms_medians"])
    steps = list(r["ms_medians"][configs[0]])
    rows = [[step, *(ms(r["ms_medians"][c][step]) for c in configs)] for step in steps]
    return (f"suzanne-251k, {r['size'][0]}x{r['size'][1]}, one point light at {tuple(r['light'])}; medians of "
            f"{r['runs']} runs each (each row its own median, so the rows need not add up).\n\n"
            + table(["step", *configs], rows) + "\n\n" + provenance(data["profile_seed000"]))


def bench_render_block(data):
    if "bench_render" not in data:
        return missing("bench_render", "python benchmarks/bench_render.py")
    r = data["bench_render"]["results"]
    samples = r["samples"]
    cells = {}
    for row in r["rows"]:
        if row.get("error_target") is None:
            cells[(row["method"], row["samples"])] = f"{row['rmse']:.4f} / {row['seconds']:.2f}"
    methods = list(dict.fromkeys(row["method"] for row in r["rows"] if row.get("error_target") is None))
    parts = [f"{r['scene']}, {r['size']}x{r['size']} AO, ao_distance {r['ao_distance']:g}, RMSE on hit pixels "
             f"against a {r['reference_samples']}-spp reference / seconds (build + render (+ denoise)), "
             f"medians of {r['runs']} runs:\n",
             table(["method", *[f"{s} spp" for s in samples]],
                   [[m, *[cells.get((m, s), "-") for s in samples]] for m in methods])]
    adaptive = [row for row in r["rows"] if row.get("error_target") is not None]
    if adaptive:
        parts += ["", "Adaptive rows (ours: error target; Cycles: its adaptive threshold):\n",
                  table(["method", "target", "max spp", "mean spp", "RMSE", "seconds"],
                        [[row["method"], row["error_target"], row["samples"], _mean_samples(row),
                          f"{row['rmse']:.4f}", f"{row['seconds']:.2f}"] for row in adaptive])]
    if r["time_ratio_at_equal_rmse"]:
        default = f" ours default: `{r['default_method']}`, the add-on's setup;" if r.get("default_method") else ""
        parts += ["", "Our time / Cycles' time at Cycles' RMSE (`<= x`: Cycles is less accurate than our fastest "
                  f"row, whose ratio is given;{default} raw and denoised: interpolated on the Pareto front of all our rows, "
                  "which may pass above one setup's own interpolation):\n",
                  table(["Cycles", "Cycles spp", "Cycles RMSE", "Cycles s", "ours raw", "ours denoised",
                         "ours default"],
                        [[_cycles_kind(e), e["cycles_samples"], f"{e['cycles_rmse']:.4f}",
                          f"{e['cycles_seconds']:.2f}", e["ours_raw"], e["ours_denoised"], e["ours_default"]]
                         for e in r["time_ratio_at_equal_rmse"]])]
    if r.get("denoiser_bias_rmse") is not None:
        parts += ["", f"Denoiser bias at convergence (RMSE between the reference and the denoised reference): "
                  f"{r['denoiser_bias_rmse']:.5f}."]
    parts += ["", provenance(data["bench_render"])]
    return "\n".join(parts)


def _mean_samples(row):
    return "-" if row.get("mean_samples") is None else f"{row['mean_samples']:.1f}"


def _cycles_kind(entry):
    """'fixed', or 'adaptive <threshold>' for a ratio against Cycles' adaptive sampling."""
    t = entry.get("cycles_adaptive_threshold")
    return "fixed" if t is None else f"adaptive {t:g}"


def first_use_block(data):
    """The README's first-use sentence: enable to image with the kernels cold and warm, the kernels' share."""
    if "bench_first_render" not in data:
        return missing("bench_first_render", "python benchmarks/bench_first_render.py --how blender --runs 3")
    r = data["bench_first_render"]["results"]
    parts = []
    for state, words in (("cold", "with an empty kernel cache"), ("warm", "with the kernels cached")):
        if state in r:
            f = r[state]
            parts.append(f"{words}, {f['enable_to_image_s']['median']:.1f} s from enabling to the image, of which "
                         f"{f['kernels_ms']['median'] / 1e3:.1f} s the kernels' compile and load")
    runs = len(next(iter(r[k] for k in ("cold", "warm") if k in r))["enable_to_image_s"]["runs"])
    how_many = "one run each" if runs == 1 else f"medians of {runs} runs"
    return ("Measured with the bpy module on the factory startup scene (" + how_many + "): "
            + "; ".join(parts) + ".\n" + provenance(data["bench_first_render"]))


def instances_block(data):
    """docs/benchmarks.md: scattered instances end to end (first and static frame, peak memory) and the
    10M-triangle meshes' build."""
    if "bench_instances" not in data:
        return missing("bench_instances", "python benchmarks/bench_instances.py --end-to-end")
    r = data["bench_instances"]["results"]
    rows = []
    for key in sorted(r, key=lambda k: (int(k.split("_")[0]), k)):
        f = r[key]
        count, path = key.split("_")
        rows.append([f"{int(count):,} ({path})", f"{f['first_total_ms'] / 1e3:.2f} s", ms(f["first_extract_ms"]),
                     f"{ms(f['first_build_ms'])} (top {ms(f['first_top_build_ms'])}, "
                     f"{f['first_top_references_per_instance']:.2f} refs/instance)", ms(f["first_trace_ms"]),
                     ms(f["static_total_ms"]), f"{f['peak_mb'] / 1024:.2f} GB", str(f["runs"]),
                     f"{sorted(f['load'])[len(f['load']) // 2]:.1f}"])
    out = table(["instances (reading path)", "first frame", "extract", "build", "trace", "static frame",
                 "peak memory", "runs", "load average"], rows) + "\n\n" + provenance(data["bench_instances"])
    if "bench_big_mesh" in data:
        b = data["bench_big_mesh"]["results"]
        lines = [f"- {name}: {f['triangles']:,.0f} triangles, build {f['build_ms'] / 1e3:.2f} s (median of "
                 f"{len(f['build_ms_runs'])}), {f['refs_per_triangle']:.2f} references and "
                 f"{f['bytes_per_triangle']:.0f} peak bytes a triangle" for name, f in b.items()]
        out += "\n\nOne 10M-triangle mesh, default build:\n" + "\n".join(lines) + "\n\n" + provenance(
            data["bench_big_mesh"])
    return out


BLOCKS = {README: {"figures": figures_block, "first-use": first_use_block},
          BENCH_DOC: {"bench_core": bench_core_block, "bench_seed000": bench_seed000_block,
                      "profile_seed000": profile_seed000_block,
                      "bench_render": bench_render_block, "bench_instances": instances_block}}


def replace_block(text, name, body):
    """`text` with the lines between NAME's begin and end markers replaced by `body`."""
    pattern = re.compile(rf"(<!-- {name}:begin -->\n).*?(<!-- {name}:end -->)", re.S)
    if not pattern.search(text):
        raise SystemExit(f"no <!-- {name}:begin --> ... <!-- {name}:end --> markers")
    return pattern.sub(lambda m: m.group(1) + body.rstrip("\n") + "\n" + m.group(2), text, count=1)


def render(path, blocks, data):
    text = Path(path).read_text(encoding="utf-8")
    for name, make in blocks.items():
        text = replace_block(text, name, make(data))
    return text


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if a generated block is out of date")
    ap.add_argument("--results", default=str(OUT_DIR), help="folder of the JSON results")
    args = ap.parse_args(argv)
    data = load(args.results)
    stale = []
    for path, blocks in BLOCKS.items():
        new = render(path, blocks, data)
        if new != path.read_text(encoding="utf-8"):
            stale.append(path)
            if not args.check:
                path.write_text(new, encoding="utf-8")
    if args.check:
        for path in stale:
            print(f"{path.relative_to(ROOT)}: generated tables differ from benchmarks/out/*.json "
                  "(run python benchmarks/report.py)")
        return 1 if stale else 0
    for path in stale:
        print(f"updated {path.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
