"""Curved test meshes of many small faces (``MeshInput``), for the cases where most faces are
smaller than a hemi-cube pixel or are grouped into clusters. The two spheres differ in how they
are built (ring order, fan winding, reflectance); each keeps the faces the tests using it were
written for."""
import numpy as np

from hemicube_radiosity.core.mesh.patches import MeshInput


def sphere(n, radius=0.3, at=(1.0, 1.0, 0.3)):
    """A UV sphere of n x 2n quads (triangle fans at the poles), outward, as a curved mesh of
    tiny faces: most cover no hemi-cube pixel centre from across the box."""
    th = np.linspace(0, np.pi, n + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, 2 * n, endpoint=False)
    t, p = np.meshgrid(th, ph, indexing="ij")
    ring = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)
    verts = np.concatenate([ring, [[0, 0, 1], [0, 0, -1]]]) * radius + np.asarray(at)
    top, bot = len(ring), len(ring) + 1
    m = 2 * n
    faces = []
    for i in range(n - 2):
        for j in range(m):
            a, b = i * m + j, i * m + (j + 1) % m
            faces.append([a, a + m, b + m, b])
    for j in range(m):
        faces.append([top, j, (j + 1) % m])
        faces.append([bot, (n - 2) * m + (j + 1) % m, (n - 2) * m + j])
    return MeshInput.from_faces(verts, faces, rho=(0.7, 0.7, 0.7), name="Sphere")


def uv_sphere(nu, nv):
    """A unit UV sphere at the origin: nu segments around, nv rings (triangle fans at the poles)."""
    th = np.linspace(0, np.pi, nv + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    t, f = np.meshgrid(th, ph, indexing="ij")
    v = np.stack([np.sin(t) * np.cos(f), np.sin(t) * np.sin(f), np.cos(t)], -1).reshape(-1, 3)
    v = np.vstack([v, [(0, 0, 1), (0, 0, -1)]])
    top, bot = len(v) - 2, len(v) - 1
    idx = lambda i, j: i * nu + j % nu
    faces = [[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)] for i in range(nv - 2) for j in range(nu)]
    faces += [[top, idx(0, j), idx(0, j + 1)] for j in range(nu)]
    faces += [[bot, idx(nv - 2, j + 1), idx(nv - 2, j)] for j in range(nu)]
    return MeshInput.from_faces(v, faces, name="sphere")
