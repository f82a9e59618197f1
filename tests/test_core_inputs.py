"""Bad input: clear errors naming the first bad index or the expected shape, never a crash."""
import warnings

import numpy as np
import pytest

import core
from core.render.denoise import FilterSettings


@pytest.fixture
def tree():
    rng = np.random.default_rng(0)
    return core.build_kdtree(rng.normal(size=(50, 3, 3)))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_triangle_is_named(bad):
    tris = np.zeros((10, 3, 3))
    tris[:, 1, 0] = 1
    tris[:, 2, 1] = 1
    tris[7, 2, 1] = bad
    with pytest.raises(ValueError, match="triangle 7 "):
        core.build_kdtree(tris)


@pytest.mark.parametrize("shape", [(10, 3), (10, 4, 3), (10, 3, 2), (3, 3, 3, 1)])
def test_wrong_triangle_shape(shape):
    with pytest.raises(ValueError, match=r"\(N, 3, 3\)"):
        core.build_kdtree(np.zeros(shape))


def test_wrong_triangle_dtype():
    with pytest.raises(ValueError, match=r"triangles must be real numbers \(float32 or float64; integers are taken"):
        core.build_kdtree(np.zeros((2, 3, 3), dtype=complex))


def test_float64_and_float32_give_same_tree():
    rng = np.random.default_rng(1)
    tris = rng.normal(size=(300, 3, 3))
    a, b = core.build_kdtree(tris), core.build_kdtree(tris.astype(np.float32))
    np.testing.assert_array_equal(a.split, b.split)


@pytest.mark.parametrize("which", ["origins", "directions"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_ray_is_named(tree, which, bad):
    o, d = np.zeros((5, 3)), np.ones((5, 3))
    (o if which == "origins" else d)[3, 1] = bad
    with pytest.raises(ValueError, match="ray 3 "):
        core.intersect(tree, o, d)
    with pytest.raises(ValueError, match="ray 3 "):
        core.occluded(tree, o, d)


def test_zero_direction_is_named(tree):
    d = np.ones((4, 3))
    d[2] = [0.0, -0.0, 0.0]
    with pytest.raises(ValueError, match="ray 2 has a zero direction"):
        core.intersect(tree, np.zeros((4, 3)), d)


def test_too_short_direction_is_named(tree):
    d = np.ones((4, 3))
    d[1] = [1e-45, 0.0, -1e-30]
    with pytest.raises(ValueError, match="ray 1 has a direction too short"):
        core.occluded(tree, np.zeros((4, 3)), d)


@pytest.mark.parametrize("o_shape, d_shape", [((5,), (5,)), ((5, 2), (5, 2)), ((5, 3), (4, 3))])
def test_ray_shapes(tree, o_shape, d_shape):
    with pytest.raises(ValueError, match=r"\(R, 3\)"):
        core.intersect(tree, np.zeros(o_shape), np.ones(d_shape))


def test_ray_limits(tree):
    o, d = np.zeros((3, 3)), np.ones((3, 3))
    with pytest.raises(ValueError, match="tmin must be >= 0; ray 1"):
        core.intersect(tree, o, d, tmin=np.array([0.0, -1.0, 0.0]))
    with pytest.raises(ValueError, match="tmax must be a scalar or have shape"):
        core.intersect(tree, o, d, tmax=np.ones(4))
    with pytest.raises(ValueError, match="tmax of ray 0 is NaN"):
        core.intersect(tree, o, d, tmax=np.array([np.nan, 1, 1]))
    for name in ("tmin", "tmax"):  # None must not become NaN, nor a string be parsed
        for bad in (None, "0.5"):
            with pytest.raises(ValueError, match=f"{name} must be a number or an array of numbers, got {bad!r}"):
                core.intersect(tree, o, d, **{name: bad})


def test_an_empty_ray_interval_misses():
    """tmax <= tmin (a per-ray limit such as a light's distance may come out so) is a valid empty
    interval, not an error: the ray misses, whatever lies on it."""
    tree = core.build_kdtree(np.array([[[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]]]))
    o, d = np.array([[0.0, 0.0, 5.0]] * 4), np.array([[0.0, 0.0, -1.0]] * 4)
    assert (core.intersect(tree, o, d).prim == 0).all()  # the triangle at t = 5
    hits = core.intersect(tree, o, d, tmin=np.array([0.0, 9.0, 3.0, 0.0]), tmax=np.array([9.0, 2.0, 3.0, -np.inf]))
    assert hits.prim[0] >= 0 and (hits.prim[1:] == -1).all()
    assert not core.occluded(tree, o[1:], d[1:], tmin=9.0, tmax=2.0).any()


def test_empty_ray_batch(tree):
    h = core.intersect(tree, np.zeros((0, 3)), np.zeros((0, 3)))
    assert h.t.shape == (0,) and h.prim.dtype == np.int32


def _box_mesh():
    tris = np.random.default_rng(1).normal(size=(20, 3, 3))
    return tris.reshape(-1, 3), np.arange(60).reshape(-1, 3)


@pytest.mark.parametrize("call, message", [
    (lambda t: core.intersect(None, np.zeros((1, 3)), np.ones((1, 3))), "tree must be a core.KdTree, got NoneType"),
    (lambda t: core.intersect(core.build_scene([_box_mesh()], [0], np.eye(4)[None]), np.zeros((1, 3)),
                              np.ones((1, 3))), "use core.intersect_scene"),
    (lambda t: core.build_scene([_box_mesh()], [2], np.eye(4)[None]), "instance 0 names mesh 2, but there are 1"),
    (lambda t: core.build_scene([_box_mesh()], [-1], np.eye(4)[None]), "instance 0 names mesh -1"),
    (lambda t: core.build_scene([_box_mesh()] * 2, np.array([0, 2**32 + 1]), np.stack([np.eye(4)] * 2)),
     "instance 1 names mesh 4294967297"),  # an int32 cast would wrap it to mesh 1
    (lambda t: core.build_two_level([t], np.array([-2**32]), np.eye(4)[None]), "instance 0 names mesh -4294967296"),
    (lambda t: core.build_scene([_box_mesh()], [0], np.full((1, 4, 4), np.nan)), "instance 0 has a non-finite matrix"),
    (lambda t: core.build_scene([_box_mesh()], [0, 0], np.eye(4)[None]), r"matrices must have shape \(2, 4, 4\)"),
    (lambda t: core.build_scene([(_box_mesh()[0], _box_mesh()[1] * 1.0)], [0], np.eye(4)[None]),
     "triangles must be integer vertex indices"),
    (lambda t: core.build_scene([_box_mesh()], [0], np.eye(4)[None], origin=(1, 2)), "origin must be 3 finite"),
    (lambda t: core.build_two_level([t], [0.7], np.eye(4)[None]), "mesh_of must hold integer mesh indices"),
    (lambda t: core.build_two_level([t], [0], np.array([[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0.5, 2]]])),
     "instance 0's matrix is not affine"),
    (lambda t: core.Camera(np.eye(4), ortho_scale=np.inf), "ortho_scale must be finite and > 0"),
    (lambda t: core.Camera(np.eye(3), 0.5), r"camera matrix_world must be a 4x4 matrix, got shape \(3, 3\)"),
    (lambda t: core.Camera(np.where(np.eye(4) == 1, np.nan, 0.0), 0.5), "camera matrix_world has a NaN or inf entry"),
    (lambda t: core.Camera(np.eye(4), 0.5, shift=(1e300, 0.0)), r"shift must be two numbers \(x, y\) within"),
    (lambda t: core.Camera(np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 5], [0, 0, 1, 0.0]]), 0.5),
     "must be affine"),
    (lambda t: core.Camera(np.diag([1.0, 1.0, 0.0, 1.0]), 0.5), "singular"),
    (lambda t: core.Camera(np.array([[1, 1, 0, 0], [0, 1e-12, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]]), 0.5), "singular"),
    # each names its setting (not a bare TypeError, or a message that names none)
    (lambda t: core.intersect(t, np.zeros((1, 3)), np.ones((1, 3)), threads=1.5), "threads must be None or an integer"),
    (lambda t: core.render_preview(t, core.Camera(np.eye(4), 0.5), 4, 4, ambient="0.5"), r"ambient must be in \[0, 1\]"),
    (lambda t: core.render_preview(t, core.Camera(np.eye(4), 0.5), 4, 4, mode="shadow",
                                   lights=core.Light.sun((0, 0, -1))), r"pass \[light\]"),
    (lambda t: core.Light.point((0, 0, 1), color=(1, 1)), r"light color must be 3 finite non-negative numbers \(r, g, b\)"),
    (lambda t: core.Light.sun((0, 0, -1), color="red"), r"light color must be 3 finite .* got 'red'"),
    (lambda t: core.build_kdtree([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 0, 0], [1, 0]]]),
     r"triangles must be an \(N, 3, 3\) array of numbers"),  # ragged: numpy's own message named nothing
    # a colour beyond float32 would make inf pixels
    (lambda t: core.Light.point((0, 0, 3), color=(1e39, 1, 1)), r"light color components must be at most 3\.403e\+38"),
    (lambda t: core.build_scene([(np.zeros((4, 2)), np.array([[0, 1, 2]]))], [0], np.eye(4)[None]),
     r"mesh 0: vertices must have shape \(N, 3\), got \(4, 2\)"),
    (lambda t: core.build_kdtree(np.zeros((1, 3, 3)), memory_limit=0), "memory_limit"),
    # settings of the wrong type: named, not a TypeError or numpy's ambiguity error
    (lambda t: core.Camera(np.eye(4), "wide"), "camera fov must be a number, got 'wide'"),
    (lambda t: core.Camera(np.eye(4), np.array([0.5, 0.6])), "camera fov must be a number"),
    (lambda t: core.Camera(np.eye(4), 0.5, clip_end="far"), "camera clip_end must be a number"),
    (lambda t: core.Camera(np.eye(4), ortho_scale=True), "camera ortho_scale must be a number"),
    (lambda t: core.Light.point((0, 0, 1), radius="big"), "point light radius must be a number"),
    (lambda t: core.Light.point((0, 0, 1), power="a"), "light power must be a number"),
    (lambda t: core.Light.spot((0, 0, 1), (0, 0, -1), "x"), "spot_size must be a number"),
    (lambda t: core.Light.sun((0, 0, -1), angle=None), "sun angle must be a number"),
    (lambda t: core.Light.area(np.array([[1, 1, 0, 0], [0, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])),
     "parallel axes"),
    # refused, naming the argument
    (lambda t: core.Light.area(np.diag([1.0, 1.0, 1.0, 2.0])), r"must be affine \(bottom row 0 0 0 1\)"),
    (lambda t: core.Light.area(np.array([[1, 0, 1, 0], [0, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1.0]])),
     "emits along its own plane"),
    (lambda t: core.Light.spot((0, 0, 1), (0, 0, -1), 1.0, axes=np.array([[1, 1, 0], [0, 0, 0], [0, 0, 1.0]])),
     "spot axes are parallel"),
    (lambda t: core.Light.area(np.eye(4), shape=["SQUARE"]), r"area light shape must be one of .* got \['SQUARE'\]"),
    (lambda t: core.Light.point("abc"), "point light position must be 3 finite numbers, got 'abc'"),
    (lambda t: core.Light.sun("down"), "sun direction must be 3 finite numbers, got 'down'"),
    (lambda t: core.Light.point((0, 0, 5)).translated([np.nan, 0, 0]), r"offset must be 3 finite numbers, got \[nan"),
    (lambda t: core.Light.point((0, 0, 5)).translated([1, 0]), r"offset must be 3 finite numbers, got \[1\.0, 0\.0\]"),
    (lambda t: core.Light.point((-1.7e308, 0, 0)).translated([1.7e308, 0, 0]),
     "the translated light's position must be 3 finite numbers"),
    (lambda t: core.Light.area("x"), "area light matrix_world must be a finite 4x4 matrix, got 'x'"),
    (lambda t: core.render_preview(t, core.Camera(np.eye(4), 0.5), 4, 4, ao_distance="1"),
     "ao_distance must be a number"),
    (lambda t: core.Camera(np.eye(4), 0.5).rays(0, 4), r"width must be an integer in \[1, 32768\], got 0"),
    (lambda t: core.Camera(np.eye(4), 0.5).rays(4, -2), r"height must be an integer in \[1, 32768\], got -2"),
])
def test_scene_camera_and_query_inputs_are_named(tree, call, message):
    with pytest.raises(ValueError, match=message):
        call(tree)


def test_a_tiny_camera_scale_is_ignored_like_any_other_scale(tree):
    """Blender ignores a camera's object scale; a uniform 1e-5 is not refused as singular."""
    m = np.diag([1e-5, 1e-5, 1e-5, 1.0])
    m[:3, 3] = (0.0, 0.0, 3.0)
    unit = m.copy()
    unit[:3, :3] = np.eye(3)
    np.testing.assert_array_equal(core.render_preview(tree, core.Camera(m, 0.8), 8, 8, samples=2),
                                  core.render_preview(tree, core.Camera(unit, 0.8), 8, 8, samples=2))


def test_scene_keeps_its_origin():
    scene = core.build_scene([_box_mesh()], [0], np.eye(4)[None], origin=(0.0, 0.0, 100.0))
    np.testing.assert_array_equal(scene.origin, (0.0, 0.0, 100.0))
    np.testing.assert_array_equal(core.build_scene([_box_mesh()], [0], np.eye(4)[None]).origin, 0.0)


def test_numpy_scalars_are_accepted_and_huge_vectors_normalised(tree):
    a = core.build_kdtree(tree.triangles, leaf_size=np.int64(4), clip=np.True_, cost_ratio=np.float32(1.0))
    b = core.build_kdtree(tree.triangles, leaf_size=4)
    assert all(np.array_equal(x, y) for x, y in zip(a.node_arrays, b.node_arrays))
    sun = core.Light.sun((1e300, 1e300, 0.0))  # the norm would overflow to inf
    np.testing.assert_allclose(sun.params["direction"], [2 ** -0.5, 2 ** -0.5, 0.0])
    with pytest.raises(core.MemoryLimitError, match="above the memory limit of 1 bytes"):
        core.build_kdtree(tree.triangles, memory_limit=1)


def test_hits_beyond_float32s_range_of_t_are_named_and_tiny_ones_kept():
    """A hit at t = 1e45 would read as t = inf (a miss) once rounded to float32: it raises, naming the
    ray, for trees and scenes alike. One at 5e-300 (or 3.5e-46, a ray just behind a triangle with a
    subnormal vertex, found by hypothesis) would round to 0, outside (tmin, tmax): it is float32's
    smallest subnormal instead, still a hit."""
    tree = core.build_kdtree(np.array([[[-1, -1, 0], [1, -1, 0], [0, 1, 0]]], np.float32))
    o, d = np.array([[0.0, 0.0, 0.0], (0.1, 0.2, 1e30)]), np.array([[0.0, 0.0, 1.0], (0.0, 0.0, -1e-15)])
    for query in (core.intersect, core.intersect_scene):
        with pytest.raises(ValueError, match="ray 1 hits at t = 1e\\+45, beyond float32's range"):
            query(tree, o, d)
    tiny = np.float32(1.4e-45)
    subnormal = core.build_kdtree(np.array([[[1.25, 0, 0], [-1.5, 0, 1], [0, 4.203895392974451e-45, 1]]]))
    for tree, origin, direction in ((tree, (0.1, 0.2, 5.0), (0.0, 0.0, -1e300)),
                                    (subnormal, (0.0, 0.0, 0.5), (0.0, 1.0, 0.0))):
        for query in (core.intersect, core.intersect_scene):
            hits = query(tree, np.array([origin]), np.array([direction]))
            assert hits.prim[0] == 0 and hits.t[0] == tiny


def test_a_hit_t_rounding_onto_the_intervals_ends_is_moved_inside():
    """A hit at t = 1 - 1e-9 with tmax 1 rounds to float32 t = 1.0, outside the open interval
    (tmin, tmax), where a caller filtering on t < tmax would lose it: it is moved inside. Likewise at
    tmin."""
    tree = core.build_kdtree(np.array([[[-1, -1, 0], [1, -1, 0], [0, 1, 0]]], np.float32))
    down = np.array([[0.0, 0.0, -1.0]])
    for query in (core.intersect, core.intersect_scene):
        hits = query(tree, np.array([[0.0, 0.0, 1.0 - 1e-9]]), down, tmax=1.0)
        assert hits.prim[0] == 0 and hits.t[0] < 1.0 and hits.t[0] == np.nextafter(np.float32(1), np.float32(0))
        hits = query(tree, np.array([[0.0, 0.0, 3.0 + 1e-9]]), down, tmin=np.array([3.0]))
        assert hits.prim[0] == 0 and hits.t[0] > 3.0 and hits.t[0] == np.nextafter(np.float32(3), np.float32(4))


def test_a_render_larger_than_the_machine_is_refused_before_allocating(tree):
    """32768 x 32768 passes the resolution check but would need ~300 GB: refused up front, naming it."""
    from core import memory
    ram = memory.physical_memory()
    if ram is None or ram > memory.render_bytes(32768, 32768):
        pytest.skip("this machine could hold the render")
    camera = core.Camera(np.eye(4), 0.5)
    with pytest.raises(core.MemoryLimitError, match="a 32768x32768 render needs about .* MB, above the memory"):
        core.PreviewRender(tree, camera, 32768, 32768)


def test_progressive_calls_name_bad_arguments(tree):
    render = core.PreviewRender(tree, core.Camera(np.eye(4), 0.5), 4, 4, samples=4)
    for bad in (2.5, 0, True, "2"):
        with pytest.raises(ValueError, match="step\\(samples\\): samples must be an integer >= 1"):
            render.step(bad)
    with pytest.raises(ValueError, match="denoise must be True or False"):
        render.image(denoise="yes")
    assert render.step(2) == 2 and render.samples_done == 2


@pytest.mark.parametrize("layout", ["auto", "flat", "two_level"])
def test_a_non_finite_vertex_names_its_mesh_and_triangle_in_every_layout(layout):
    """The error names the caller's mesh and triangle, also in a soup, where merging would otherwise
    spread the NaN and name triangle 0 of the soup."""
    good, bad = _box_mesh(), _box_mesh()
    bad[0][16, 2] = np.nan  # vertex 16: triangle 5's second vertex
    with pytest.raises(ValueError, match=r"mesh 1: triangle 5 has a non-finite vertex coordinate \(NaN or inf\): "
                                         r"\[\[.*\], \[.*, nan\], \[.*\]\]"):
        core.build_scene([good, bad], [0, 1], np.stack([np.eye(4)] * 2), layout=layout)
    unused = (np.concatenate([good[0], [[np.inf, 0.0, 0.0]]]), good[1])
    with pytest.raises(ValueError, match=r"mesh 1: vertex 60 is not finite: \[inf, 0.0, 0.0\]"):
        core.build_scene([good, unused], [0, 1], np.stack([np.eye(4)] * 2), layout=layout)


def test_a_vertex_beyond_float32_range_is_named_as_such():
    """A finite float64 vertex of 1e39 is named as beyond float32's range, not as "non-finite (NaN or
    inf)" (which a cast to float32 first would make it, with a warning)."""
    tris = np.random.default_rng(2).normal(size=(4, 3, 3))
    tris[2, 1, 0] = 1e39
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy overflow warning on the way
        with pytest.raises(ValueError, match=r"triangle 2 has a vertex coordinate beyond float32's range "
                                             r"\(\+-3\.403e\+38\).*1e\+39"):
            core.build_kdtree(tris)
        vertices, triangles = _box_mesh()
        vertices[7, 2] = -2e38 * 10
        for layout in ("flat", "two_level"):
            with pytest.raises(ValueError, match=r"mesh 0: vertex 7 is beyond float32's range"):
                core.build_scene([(vertices, triangles)], [0], np.eye(4)[None], layout=layout)


@pytest.mark.parametrize("args, word", [((-4, 4, "ao", 16), "width"), ((4, 4, "ao", 0), "samples"),
                                        ((4, 4, "ao", 2.7), "samples"), ((4, 4, "ao", "16"), "samples"),
                                        ((4, 4, "shadow", 16, []), "light"), ((4, 4, "sky", 16), "mode")])
def test_frame_ray_count_refuses_what_the_renderer_refuses(args, word):
    """Unchecked, it would return -272, 16, 48, 272 and 16 for the first five."""
    with pytest.raises(ValueError, match=word):
        core.frame_ray_count(*args)


def test_lights_that_are_not_a_list_are_named(tree):
    with pytest.raises(ValueError, match="lights must be a list of core.Light, got None"):
        core.render_preview(tree, core.Camera(np.eye(4), 0.8), 4, 4, mode="shadow", lights=None)


def denoise_inputs(pixels, counts=(1, 1)):
    n = len(pixels)
    return (2, 2, np.asarray(pixels), np.zeros((n, 3)), np.tile([[0.0, 0.0, 1.0]], (n, 1)), np.full((n, 3), 0.5),
            np.full(n, 0.25), np.asarray(counts))


@pytest.mark.parametrize("pixels, counts, word", [([0, -1], (1, 1), r"pixels must be in \[0, 4\)"),
                                                  ([0, 9], (1, 1), r"pixels must be in \[0, 4\)"),
                                                  ([0.0, 1.0], (1, 1), "integer pixel indices"),
                                                  ([0, 1], (1, -3), r"counts must be >= 0 .*got -3.0 at row 1"),
                                                  ([0, 1], (1,), r"counts must have shape \(2,\)"),
                                                  ([3, 3], (1, 1), "each pixel once, got pixel 3 2 times"),
                                                  ([0, 1], (np.nan, 1), r"counts must be finite, got nan at row 0")])
def test_denoise_pixels_names_bad_inputs(pixels, counts, word):
    """A negative index must not wrap round and light the last pixel, nor a negative count pass."""
    with pytest.raises(ValueError, match=word):
        core.denoise_pixels(*denoise_inputs(pixels, counts))
    assert core.denoise_pixels(*denoise_inputs([0, 3]))[..., 3].tolist() == [[1.0, 0.0], [0.0, 1.0]]
    listed = list(denoise_inputs([0, 3]))
    listed[2] = [0, 3]  # a list of indices, as numpy takes them
    np.testing.assert_array_equal(core.denoise_pixels(*listed), core.denoise_pixels(*denoise_inputs([0, 3])))
    empty = list(denoise_inputs([], counts=()))
    empty[2] = np.zeros(0)  # no hit pixels, whatever the empty array's dtype
    assert not core.denoise_pixels(*empty).any()


@pytest.mark.parametrize("argument, value, word", [
    (0, -2, "width must be an integer"), (1, 2.5, "height must be an integer"), (0, "2", "width must be an integer"),
    (3, np.full((2, 3), np.nan), r"points must be finite, got \[nan, nan, nan\] at row 0"),
    (4, np.array([[0, 0, 1.0], [0, np.inf, 1]]), r"normals must be finite, got \[0.0, inf, 1.0\] at row 1"),
    (5, np.full((2, 3), np.inf), "sums must be finite"), (6, np.array([0.25, -1.0]), "sq_sums must be >= 0"),
    (3, np.array([["a", "b", "c"]] * 2), "points must be an array of numbers, got dtype <U1"),
    (5, np.zeros((2, 3), complex), "sums must be an array of numbers")])
def test_denoise_pixels_names_bad_arrays(argument, value, word):
    """Unchecked, NaN points and inf sums gave NaN or inf pixels, a string width or array passed through
    int() or numpy's own message, and a negative size named the pixels."""
    args = list(denoise_inputs([0, 3]))
    args[argument] = value
    with pytest.raises(ValueError, match=word):
        core.denoise_pixels(*args)


@pytest.mark.parametrize("keywords, word", [
    ({"variance_decay": np.nan}, r"variance_decay must be in \[0, 1\]"),
    ({"variance_decay": -5}, r"variance_decay must be in \[0, 1\]"), ({"variance_decay": "0.5"}, "must be a number"),
    ({"settings": (1, 2)}, "settings must be a FilterSettings"),
    ({"settings": FilterSettings(iterations=2.0)}, "settings.iterations must be an integer"),
    ({"settings": FilterSettings(iterations=40)}, "settings.iterations must be an integer in"),
    ({"settings": FilterSettings(sigma_plane=0.0)}, "settings.sigma_plane must be a positive number, got 0.0")])
def test_denoise_pixels_names_bad_settings(keywords, word):
    with pytest.raises(ValueError, match=word):
        core.denoise_pixels(*denoise_inputs([0, 3]), **keywords)
    assert core.denoise_pixels(*denoise_inputs([0, 3]), variance_decay=0.5,
                               settings=FilterSettings(iterations=0)).shape == (2, 2, 4)


def test_scene_builder_inputs_that_are_not_mesh_inputs_or_hashable_keys_are_named():
    v, f = np.eye(3), np.array([[0, 1, 2]])
    builder = core.SceneBuilder()
    with pytest.raises(ValueError, match=r"meshes\[0\] must be a core.MeshInput"):
        builder.build([(v, f)], [0], np.eye(4)[None])
    with pytest.raises(ValueError, match="mesh keys must be hashable"):
        builder.build([core.MeshInput(["unhashable"], v, f, 0)], [0], np.eye(4)[None])
    for fingerprint in (np.zeros(3), [1, 2]):  # an array would fail only on the second frame, unnamed
        with pytest.raises(ValueError, match=f"mesh 'm': fingerprint must be hashable .*got {type(fingerprint).__name__}"):
            builder.build([core.MeshInput("m", v, f, fingerprint)], [0], np.eye(4)[None])


@pytest.mark.parametrize("vertices, dtype", [(np.eye(3) + 5j, "complex128"), (np.eye(3, dtype=bool), "bool"),
                                             (np.eye(3).astype(str), "<U32")])
def test_scene_vertices_that_are_not_real_numbers_are_named(vertices, dtype):
    """build_scene names complex, bool and string vertices, as build_kdtree does (rather than drop
    imaginary parts, take bools or fail in numpy on strings)."""
    with pytest.raises(ValueError, match=f"mesh 0: vertices must be real numbers .*got dtype {dtype}"):
        core.build_scene([(vertices, np.array([[0, 1, 2]]))], [0], np.eye(4)[None])


@pytest.mark.parametrize("layout", ["auto", "two_level", "flat"])
def test_a_lazy_scene_is_one_tree_or_a_named_refusal(layout):
    """A lazy build has to be the scene's one tree. Layout "auto" would keep a mesh placed twice apart
    from the soup of the others, and a refusal must name the caller's mesh, not an internal tree.
    "auto" and "flat" merge everything into one lazy tree, which answers as the eager scene does;
    "two_level" is refused naming the caller's meshes."""
    tri = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), np.array([[0, 1, 2]]))
    quad = (np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], np.float32), np.array([[0, 1, 2], [0, 2, 3]]))
    mats = np.stack([np.eye(4)] * 3)
    mats[2, 0, 3] = 5.0
    if layout == "two_level":
        with pytest.raises(ValueError, match=r"layout 'two_level' keeps meshes \[0, 1\] apart"):
            core.build_scene([tri, quad], [0, 1, 1], mats, layout=layout, lazy=True)
        return
    scene = core.build_scene([tri, quad], [0, 1, 1], mats, layout=layout, lazy=True)
    assert scene.lazy_tree is not None and scene.stats()["triangles"] == 5
    o = np.array([[0.2, 0.2, 2.0], [5.2, 0.2, 2.0], [0.2, 0.2, 0.5], [3.0, 0.0, 2.0]])
    got = core.intersect_scene(scene, o, [[0, 0, -1.0]] * 4)
    want = core.intersect_scene(core.build_scene([tri, quad], [0, 1, 1], mats, layout=layout), o, [[0, 0, -1.0]] * 4)
    np.testing.assert_array_equal(got.t, want.t)
    np.testing.assert_allclose(got.t, [1.0, 1.0, 0.5, np.inf])


@pytest.mark.parametrize("layout", ["two_level", "flat"])
def test_an_instance_placed_beyond_float32s_range_is_named(layout):
    """An instance moved 1e39 away is named, neither taken silently (two_level) nor blamed on the other
    instance's finite triangle (flat). Measured from the origin given, the same place is fine."""
    v, f = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]])
    far = np.eye(4)
    far[0, 3] = 1e39
    with pytest.raises(ValueError, match=r"instance 1 \(mesh 0\): its matrix places the mesh beyond float32's range"):
        core.build_scene([(v, f)], np.array([0, 0]), np.stack([np.eye(4), far]), layout=layout)
    core.build_scene([(v, f)], np.array([0]), far[None], origin=(1e39, 0, 0), layout=layout)
    core.build_scene([(v, f)], np.array([0, 0]), np.stack([np.eye(4), far]), layout=layout,
                     visibility=np.array([3, 0], np.uint8))  # an instance no ray meets is left out
    farther = far.copy()
    farther[0, 3] = -2e39
    with pytest.raises(core.PlacementRangeError, match=r"instance 1 \(mesh 0\) \(and 1 more\)") as raised:
        core.SceneBuilder(layout=layout).build([core.MeshInput("m", v, f, 0)], np.array([0, 0, 0, 0]),
                                               np.stack([np.eye(4), far, np.eye(4), farther]))
    assert raised.value.instances.tolist() == [1, 3]  # every one, so a caller can leave them out


def _numpy_hits_as_float32(t, prim, lo, hi):
    """The float32 rules of hits_as_float32 in NumPy, one array operation each (an independent oracle)."""
    with np.errstate(over="ignore"):
        out = t.astype(np.float32)
    hit = prim >= 0
    out[hit & (out == 0.0)] = np.nextafter(np.float32(0), np.float32(1))
    past = hit & (out >= hi)
    out[past] = np.nextafter(out[past], np.float32(-np.inf))
    before = hit & (out <= lo)
    out[before] = np.nextafter(out[before], np.float32(np.inf))
    return out


def test_the_compiled_float32_outputs_equal_numpys_rules_across_blocks():
    """hits_as_float32 (one parallel pass by blocks) against the NumPy oracle, on 3 blocks' worth of rays:
    ordinary t, t that round onto or past tmin and tmax, t below the smallest subnormal, misses (inf),
    u and v. A hit beyond float32's range is named by its index, the first of all blocks', though a
    later block holds another."""
    from core.inputs import BLOCK, hits_as_float32
    rng = np.random.default_rng(3)
    n = 3 * BLOCK + 17
    lo, hi = rng.random(n) * 2.0, np.full(n, np.inf)
    t = lo + rng.random(n) * 10.0 + 1e-12
    prim = np.where(rng.random(n) < 0.8, 7, -1).astype(np.int32)
    at_hi, at_lo, tiny = np.split(rng.permutation(n)[:1050], [500, 1000])  # three disjoint sets of rays
    hi[at_hi] = np.float64(np.float32(t[at_hi])) + rng.choice([0.0, 1e-12, -1e-12], 500) * t[at_hi]
    t[at_hi] = np.minimum(t[at_hi], np.nextafter(hi[at_hi], 0.0))
    lo[at_lo] = np.minimum(np.nextafter(np.float64(np.float32(t[at_lo])), 0.0), np.nextafter(t[at_lo], 0.0))
    lo[tiny], t[tiny] = 0.0, rng.random(50) * 1e-300
    t[prim < 0] = np.inf
    u, v = rng.random(n), rng.random(n)
    t32, u32, v32 = hits_as_float32(t, prim, u, v, lo, hi)
    np.testing.assert_array_equal(t32, _numpy_hits_as_float32(t, prim, lo, hi))
    np.testing.assert_array_equal(u32, u.astype(np.float32))
    np.testing.assert_array_equal(v32, v.astype(np.float32))
    hit = prim >= 0
    assert (t32[hit] > lo[hit]).all() and (t32[hit] < hi[hit]).all()
    beyond = np.flatnonzero(hit)[[-1, 3 * len(np.flatnonzero(hit)) // 4]]  # in the last and an earlier block
    t[beyond] = 1e45
    with pytest.raises(ValueError, match=f"ray {beyond.min()} hits at t = 1e\\+45"):
        hits_as_float32(t, prim, u, v, lo, hi)


def test_the_parallel_ray_check_names_the_first_bad_ray_of_all_blocks():
    """as_rays' compiled check runs by blocks in parallel: the ray it names is still the first bad one
    (a NaN origin in an early block beats one in a later block), and each fault is named in its order."""
    from core.inputs import BLOCK, as_rays
    n = 3 * BLOCK
    o, d = np.zeros((n, 3)), np.tile([0.0, 0.0, 1.0], (n, 1))
    o[2 * BLOCK + 5, 1] = np.nan
    o[BLOCK + 9, 0] = np.inf
    d[5, 2] = 0.0
    with pytest.raises(ValueError, match=f"origin of ray {BLOCK + 9} is not finite"):
        as_rays(o, d)
    o[:] = 0.0
    with pytest.raises(ValueError, match="ray 5 has a zero direction vector"):
        as_rays(o, d)
    d[5, 2], d[BLOCK + 3, 0] = 1.0, 2.0 ** -700
    _, fixed = as_rays(o, d)
    assert fixed[BLOCK + 3, 0] == 0.0 and fixed[BLOCK + 3, 2] == 1.0


def _strings(matrix):
    return np.asarray(matrix).astype(str)


@pytest.mark.parametrize("kind", ["strings", "complex", "bool"])
def test_matrices_of_other_than_real_numbers_are_named(kind):
    """numpy would parse strings of digits, keep a complex matrix's real part with only a warning and take
    bools as 0 and 1: each is refused with the argument's name, wherever a matrix or a point enters."""
    def bad(value):
        return {"strings": _strings, "complex": lambda m: np.asarray(m, complex),
                "bool": lambda m: np.asarray(m, bool)}[kind](value)
    vertices, triangles = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]])
    calls = [(lambda: core.build_scene([(vertices, triangles)], [0], bad(np.eye(4)[None])), "matrices .* must be"),
             (lambda: core.build_scene([(vertices, triangles)], [0], np.eye(4)[None], origin=bad([1, 2, 3])),
              "origin must be"),
             (lambda: core.Camera(bad(np.eye(4)), 0.8), "camera matrix_world must be"),
             (lambda: core.Camera(np.eye(4), 0.8, shift=bad([0.1, 0.2])), "camera shift must be"),
             (lambda: core.Camera(np.eye(4), 0.8).translated(bad([1, 2, 3])), "camera offset must be"),
             (lambda: core.Camera(np.eye(4), 0.8).translated([1, 2, 3, 4]), "camera offset must be 3 finite"),
             (lambda: core.Light.area(bad(np.eye(4))), "area light matrix_world must be"),
             (lambda: core.Light.point(bad([1, 2, 3])), "point light position must be"),
             (lambda: core.Light.spot((0, 0, 1), (0, 0, -1), 0.5, axes=bad(np.eye(3))), "spot axes must be"),
             (lambda: core.Light.point((0, 0, 1), color=bad([1, 1, 1])), "light color must be")]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's ComplexWarning would turn into an error here
        for call, word in calls:
            with pytest.raises(ValueError, match=word):
                call()
