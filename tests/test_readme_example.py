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
