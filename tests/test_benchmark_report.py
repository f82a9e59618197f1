"""benchmarks/report.py renders the docs' figure tables from benchmark JSON: checked on a small fixture
(tests/fixtures/benchmarks/), for the tables' content, not for any timing."""
from pathlib import Path

import pytest

from tests.benchmark_modules import load_benchmark

ROOT = Path(__file__).resolve().parents[1]
FIXTURE = ROOT / "tests" / "fixtures" / "benchmarks"


@pytest.fixture(scope="module")
def report():
    return load_benchmark("report")


def rows_of(block):
    return [line for line in block.splitlines() if line.startswith("| ")]


def test_the_readme_table_holds_each_headline_figure_beside_its_reference(report):
    block = report.figures_block(report.load(FIXTURE))
    rows = rows_of(block)
    assert rows[0] == "| figure | KD Preview | reference, same run |"
    assert "| kd-tree build (binned SAH), 251,906 triangles | 160 ms (SAH cost 16.50) | Embree BVH build 40.0 ms |" in rows
    assert "| camera rays, 2 threads (262,144 rays) | 2.50 Mrays/s | Embree, 1 thread: 10.00 Mrays/s (0.25x) |" in rows
    assert any(r.startswith("| seed 000's setting") and "0.210 s" in r and "0.110 s (1.91x)" in r for r in rows)
    assert any("Cycles at 16 spp" in r and "raw 0.600, denoised 0.300" in r for r in rows)
    assert "Example CPU 9000, 2 cores" in block and "2030-01-02 03:04 UTC" in block and "Quick run" not in block


def test_the_benchmark_tables_list_every_builder_configuration_and_run(report):
    data = report.load(FIXTURE)
    core_rows = rows_of(report.bench_core_block(data))
    assert [r.split(" | ")[0] for r in core_rows[2:]] == ["| binned", "| median", "| Embree (embreex, 1 thread)"]
    assert core_rows[2].split(" | ")[6] == "127"  # peak bytes a triangle
    seed_rows = rows_of(report.bench_seed000_block(data))
    assert "| rays=W*H*2 | 0.210 s | 0.050 s | 3 | 0.200, 0.210, 0.220 |" in seed_rows
    render = report.bench_render_block(data)
    assert rows_of(render)[0] == "| method | 1 spp | 4 spp | 16 spp |"
    assert any(r.startswith("| cycles ao pass |") for r in rows_of(render))
    assert "| fixed | 4 | 0.1000 | 0.50 | 0.700 | 0.450 | 0.800 |" in rows_of(render)


def test_blocks_are_replaced_between_their_markers_only(report, tmp_path):
    doc = tmp_path / "doc.md"
    doc.write_text("# Title\n\nprose\n<!-- figures:begin -->\nstale\n<!-- figures:end -->\nafter\n")
    text = report.render(doc, {"figures": report.figures_block}, report.load(FIXTURE))
    assert text.startswith("# Title\n\nprose\n<!-- figures:begin -->\n| figure |")
    assert text.endswith("<!-- figures:end -->\nafter\n") and "stale" not in text
    doc.write_text(text)  # rendering again changes nothing
    assert report.render(doc, {"figures": report.figures_block}, report.load(FIXTURE)) == text


def test_missing_results_say_which_command_makes_them(report, tmp_path):
    assert "bench_core.py" in report.figures_block(report.load(tmp_path))
    assert "--only-seed000" in report.bench_seed000_block({})


def test_check_mode_fails_when_the_committed_tables_differ_from_the_json(report):
    assert report.main(["--check", "--results", str(FIXTURE)]) == 1  # the fixture is not the committed run


def test_the_committed_tables_are_what_the_committed_json_gives(report):
    assert report.main(["--check"]) == 0, "run: python benchmarks/report.py"


def test_the_provenance_names_the_vector_extension_the_kernels_were_compiled_for(report):
    """Two hosts of one model name ("AMD EPYC") may differ in vector width, which sets the figures
    (docs/choices.md#four-and-sixteen-lanes-on-avx2-dropped): the line says LLVM's CPU and extension."""
    run = {"benchmark": "b", "date": "d", "jit_seconds": 1.0, "command": "c",
           "host": {"cpu": "AMD EPYC", "cores": 2, "numba_threads": 2, "python": "3.11", "numba": "0.68"}}
    assert "AMD EPYC, 2 cores" in report.provenance(run)  # results written before the field existed
    run["host"]["cpu_target"] = "znver4, AVX-512"
    assert "AMD EPYC (znver4, AVX-512), 2 cores" in report.provenance(run)
    results = load_benchmark("results")
    name, simd = results.host()["cpu_target"].split(", ")
    assert name and simd in ("AVX-512", "AVX2", "NEON", "no AVX2", "vector extension unknown")


def test_the_cycles_ratios_name_the_setup_the_default_column_measures(report):
    data = report.load(FIXTURE)
    data["bench_render"]["results"]["default_method"] = "kd binned rays=frame sobol"
    assert "ours default: `kd binned rays=frame sobol`, the add-on's setup" in report.bench_render_block(data)


def test_the_render_benchmarks_default_is_the_addons_setup():
    """The add-on tells each frame's build the frame's rays (kd_addon/pipeline.py), so the row the
    Cycles ratios call our default, and its denoised twin, are built so."""
    bench = load_benchmark("bench_render")
    methods = {name: (options, sampler, denoise) for name, options, sampler, denoise in bench.our_methods()}
    assert methods[bench.DEFAULT_METHOD] == ({"rays": "frame"}, "sobol", False)
    assert methods[bench.DEFAULT_METHOD + " denoised"] == ({"rays": "frame"}, "sobol", True)
    assert "kd binned sobol denoised" in methods  # the default build's rows stay, for comparison
