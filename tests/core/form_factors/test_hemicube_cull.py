"""Culling before drawing (core/form_factors/frustum.py): pieces that cannot cover a hemi-cube pixel centre
are left out before they are projected and drawn, and the item buffers stay those of drawing
every piece."""
import numpy as np
import pytest

from hemicube_radiosity.core.form_factors import frustum, pixels, raster
from hemicube_radiosity.core.form_factors import hemicube as H
from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.mesh.stage import cut_patches as _cut
from hemicube_radiosity.core.pipeline import BakeSettings
from tests.support.shapes import sphere


def _grouped(meshes):
    return _cut(meshes, BakeSettings().resolved(meshes))


def _no_clear_bits(monkeypatch):
    """vertex_codes with no vertex x- or y-clear: nothing is culled by its cell, every piece
    wholly in a face goes on to be projected (the drawing path before the cull)."""
    codes = H.vertex_codes

    def uncleared(*a):
        return codes(*a) & ~(frustum._CLEAR_X | frustum._CLEAR_Y | frustum._CELL_X | frustum._CELL_Y)

    monkeypatch.setattr(H, "vertex_codes", uncleared)


def _pixel_grid_values(rng, n, R):
    """Pixel coordinates at and a few float32 steps around the values the cull and
    :func:`raster._pixel_range` round at (centres, centres +- SNAP), and random ones."""
    k = rng.integers(-1, R + 1, n).astype(np.float32)
    base = k + np.float32(0.5) + rng.choice(np.array([0.0, raster.SNAP, -raster.SNAP, 0.3, -0.3], np.float32), n)
    steps = rng.integers(-3, 4, n)
    out = base.copy()
    for s in range(1, 4):
        up, down = steps >= s, steps <= -s
        out[up] = np.nextafter(out[up], np.float32(np.inf))
        out[down] = np.nextafter(out[down], np.float32(-np.inf))
    return np.where(rng.random(n) < 0.2, rng.uniform(-1, R + 1, n).astype(np.float32), out)


@pytest.mark.parametrize("R", [8, 32])
def test_a_polygon_culled_by_its_corners_cells_has_no_candidate_pixel(R):
    """corner_tests' ``empty`` holds only where the rasteriser's own candidate range
    (_pixel_range, which rasterise draws from) is empty, on vertices at and a float32 step
    around every rounding point; and it does cull most of the polygons with no candidate."""
    rng = np.random.default_rng(3)
    M = 200_000
    face = rng.integers(0, 5, M)
    # small polygons (a few tenths of a pixel, some a few pixels) around points on the grid
    cx, cy = _pixel_grid_values(rng, M, R), _pixel_grid_values(rng, M, R)
    size = rng.choice(np.array([0.05, 0.3, 1.0, 3.0], np.float32), M)
    px = [cx] + [cx + (rng.uniform(-1, 1, M) * size).astype(np.float32) for _ in range(2)]
    py = [cy] + [cy + (rng.uniform(-1, 1, M) * size).astype(np.float32) for _ in range(2)]
    # some corners exactly on the grid values (snapped corners can sit on a rounding point)
    for c in (1, 2):
        on = rng.random(M) < 0.3
        px[c][on] = _pixel_grid_values(rng, int(on.sum()), R)
        py[c][on] = py[0][on]
    px.append(px[2])                                                  # triangles: corner 3 = 2
    py.append(py[2])
    # corners inside their face, as every corner of a pair wholly in one face is
    # (vertex_projection): px in [-SAMPLE_X, R - SAMPLE_X], py up to the face's rows
    rows = np.array([R, R // 2, R // 2, R // 2, R // 2])[face]
    px = [np.clip(p, np.float32(-pixels.SAMPLE_X), np.float32(R - pixels.SAMPLE_X)) for p in px]
    py = [np.clip(p, np.float32(-pixels.SAMPLE_Y), (rows - pixels.SAMPLE_Y).astype(np.float32)) for p in py]
    vface = np.repeat(face[None, :], 4, axis=0).reshape(1, -1).astype(np.int8)   # (1, 4M)
    code = frustum.vertex_codes(vface, np.ones(vface.shape, np.float32),
                                np.concatenate(px)[None, :], np.concatenate(py)[None, :])
    _, whole, empty, low = frustum.corner_tests(code.reshape(1, 4, M))
    assert whole.all() and np.array_equal(low[0], face + 9)
    can = raster.can_cover(px, py, rows, R)
    assert not (empty[0] & can).any()
    # exercised: most polygons without a candidate are culled by their cells (measured 68% at
    # R = 8, 74% at R = 32, with corners this often at rounding points), and a fifth or more
    # have a candidate
    assert empty[0].sum() > 0.6 * (~can).sum() and can.sum() > M / 10


def test_culling_keeps_the_item_buffers_of_drawing_every_piece(monkeypatch):
    """Item buffers of a sphere of 3,200 tiny faces in the Cornell box: the same keys with the
    cull as with every piece wholly inside a face projected and tested by rasterise's range."""
    pieces, clusters = _grouped(scenes.cornell_box() + [sphere(40)])
    R = 32
    scene = H._Scene(pieces, R, clusters)
    frames = pixels.receiver_frames(clusters.normals)
    recv = np.arange(0, len(clusters), max(1, len(clusters) // 24))
    # how many pieces wholly inside a face the cull leaves out (it is exercised)
    culled = []
    tests = H.corner_tests

    def counting(code):
        out = tests(code)
        culled.append((int((out[1] & out[2]).sum()), int(out[1].sum())))
        return out

    monkeypatch.setattr(H, "corner_tests", counting)
    new = H._batch_item_buffer(scene, recv, frames, scene.eyes)
    monkeypatch.setattr(H, "corner_tests", tests)
    _no_clear_bits(monkeypatch)
    old = H._batch_item_buffer(scene, recv, frames, scene.eyes)
    assert np.array_equal(new, old)
    c, w = np.sum(culled, axis=0)
    assert c > 0.5 * w                                                # measured 0.76


@pytest.mark.parametrize("R", [8, 32, 64])
def test_pieces_across_faces_culled_before_clipping_keep_the_item_buffers(monkeypatch, R):
    """Pieces crossing a face's frustum whose corners' projections (widened by CLIP_MARGIN)
    hold no candidate pixel are left out before clipping: the same item buffers as clipping
    and testing every one, on the sphere of tiny faces (many straddle the faces' borders)."""
    pieces, clusters = _grouped(scenes.cornell_box() + [sphere(40)])
    scene = H._Scene(pieces, R, clusters)
    frames = pixels.receiver_frames(clusters.normals, rotate_seed=5)
    recv = np.arange(0, len(clusters), max(1, len(clusters) // 40))
    hits = []
    test = H.hull_misses_centres

    def counting(u, v, w, f, R_):
        out = test(u, v, w, f, R_)
        hits.append((int(out.sum()), out.size))
        return out

    monkeypatch.setattr(H, "hull_misses_centres", counting)
    new = H._batch_item_buffer(scene, recv, frames, scene.eyes)
    monkeypatch.setattr(H, "CLIP_CULL", False)
    old = H._batch_item_buffer(scene, recv, frames, scene.eyes)
    assert np.array_equal(new, old)
    culled, tested = np.sum(hits, axis=0)
    # exercised: of the (piece, face) pairs looked at, measured 35% at R = 8, 24% at 32, 19% at 64
    assert culled > 0.15 * tested
