"""Test geometry: closed meshes, lattices and the degenerate and extreme cases the core must survive."""
import numpy as np


def icosphere(subdivisions):
    """Unit icosphere as (vertices float64 (V, 3), faces int (F, 3)), consistently wound outward."""
    t = (1.0 + 5 ** 0.5) / 2.0
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
         (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
         (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    verts = [np.array(p, float) / np.linalg.norm(p) for p in v]
    faces = f
    for _ in range(subdivisions):
        cache = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = verts[a] + verts[b]
                verts.append(m / np.linalg.norm(m))
                cache[key] = len(verts) - 1
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    return np.array(verts), np.array(faces)


def subdivided_cube(n, half=1.0):
    """Closed cube [-half, half]^3 with every face an n x n grid of quads split into two triangles.

    With n a power of two the grid coordinates are exact in float32, so rays can aim exactly at
    vertices and along edges.
    """
    g = np.linspace(-half, half, n + 1)
    tris = []
    for axis in range(3):
        for side in (-half, half):
            u, v = np.meshgrid(g, g, indexing="ij")
            pts = np.zeros((n + 1, n + 1, 3))
            a1, a2 = (axis + 1) % 3, (axis + 2) % 3
            pts[..., axis], pts[..., a1], pts[..., a2] = side, u, v
            p00, p10, p01, p11 = pts[:-1, :-1], pts[1:, :-1], pts[:-1, 1:], pts[1:, 1:]
            quad = [np.stack([p00, p10, p11], -2), np.stack([p00, p11, p01], -2)]
            if side < 0:  # keep the winding outward
                quad = [q[..., ::-1, :] for q in quad]
            tris += [q.reshape(-1, 3, 3) for q in quad]
    return np.concatenate(tris)


def mesh_triangles(verts, faces):
    return verts[faces]


def lattice(n=4):
    """Unit squares (two triangles each) in every axis plane at integer coordinates 0..n: every box
    face, event and split candidate coincides with others."""
    tris = []
    for axis in range(3):
        a1, a2 = (axis + 1) % 3, (axis + 2) % 3
        for k in range(n + 1):
            for i in range(n):
                for j in range(n):
                    p = np.zeros((4, 3))
                    p[:, axis] = k
                    p[:, a1] = [i, i + 1, i + 1, i]
                    p[:, a2] = [j, j, j + 1, j + 1]
                    tris += [p[[0, 1, 2]], p[[0, 2, 3]]]
    return np.array(tris)


def random_soup(rng, n, size=0.1, extent=1.0):
    centres = rng.uniform(-extent, extent, (n, 1, 3))
    return centres + rng.normal(0.0, size, (n, 3, 3))


def degenerate_mix(rng):
    """Needles, slivers, zero-area triangles and stacked coplanar duplicates around a random soup."""
    soup = random_soup(rng, 300)
    needles = rng.uniform(-1, 1, (50, 1, 3)) + np.array([[0, 0, 0], [3.0, 0, 0], [3.0, 1e-4, 0]])
    a = rng.uniform(-1, 1, (50, 3))
    b = rng.uniform(-1, 1, (50, 3))
    slivers = np.stack([a, b, 0.5 * (a + b) + rng.normal(0, 1e-6, (50, 3))], axis=1)
    collinear = np.stack([a, b, 0.25 * a + 0.75 * b], axis=1)
    points = np.repeat(a[:, None, :], 3, axis=1)
    stacked = np.repeat(np.array([[[0.0, 0.0, 0.5], [1.0, 0.0, 0.5], [0.0, 1.0, 0.5]]]), 40, axis=0)
    return np.concatenate([soup, needles, slivers, collinear, points, stacked])
