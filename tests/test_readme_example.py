"""The README's core API example runs as printed (a new user's first script), and computes what its
comments say: it is taken from README.md at test time, so an API change that breaks it fails here."""
import re
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[1] / "README.md"


def core_api_example() -> str:
    text = README.read_text(encoding="utf-8")
    section = text[text.index("## Python API"):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_the_core_api_example_runs_and_means_what_its_comments_say():
    names = {}
    exec(compile(core_api_example(), str(README) + " (core API example)", "exec"), names)  # noqa: S102
    hits = names["hits"]
    assert hits.prim.tolist() in ([0], [1]) and np.isclose(hits.t[0], 5.0)  # straight down onto the quad
    assert names["blocked"].tolist() == [False]  # tmax 1.0 stops 4 units above the quad
    image = names["image"]
    assert image.shape == (512, 512, 4) and image.dtype == np.float32
    alpha = image[..., 3]
    assert 0.0 < alpha.mean() < 1.0 and set(np.unique(alpha)) == {0.0, 1.0}
    assert np.allclose(image[..., :3][alpha == 1.0], 1.0, atol=1e-6)  # a lone quad: nothing occludes its AO
    render = names["render"]
    assert render.done and render.stats()["converged_pixels"] > 0  # error_target stopped pixels early
    origins, directions, tmin, tmax = names["origins"], names["directions"], names["tmin"], names["tmax"]
    assert origins.shape == directions.shape == (640 * 480, 3) and tmin.shape == tmax.shape == (640 * 480,)


def test_the_bpy_script_example_renders_through_the_engine_and_the_panels_animation(tmp_path):
    """docs/scripting.md's script for the add-on on the bpy module (the README links it), with its clone path and output folders put in
    tmp_path, in a fresh process (the factory scene: cube, camera, light): F12's file and the Animation's
    frames and report.json appear."""
    from tests.addon_support import REPO, run_python

    text = (README.parent / "docs" / "scripting.md").read_text(encoding="utf-8")
    section = text[text.index("## The add-on from a `bpy` script"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    code = code.replace("/path/to/kd-preview", str(REPO)).replace("/tmp/kd", str(tmp_path))
    code = code.replace("scene.render.engine = ", "scene.render.resolution_percentage = 10\nscene.frame_end = 2\n"
                        "scene.render.engine = ")  # small and short, the example's own lines unchanged
    proc = run_python(code, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (tmp_path / "frame_.png").is_file()
    assert sorted(p.name for p in (tmp_path / "preview").iterdir()) == ["frame_0001.png", "frame_0002.png",
                                                                          "report.json"]
