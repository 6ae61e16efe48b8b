"""Map errors on the surface: the truth against itself on another mesh and UV layout scores ~0
and far below a perturbed copy; a known perturbation gives its known MSE; the nearest-point search
is exact (brute force over every triangle); a thin two-sided slab is read from the texel's side;
kg is compared over directions across cube sizes; the shading balls match Lambert's law."""

import numpy as np
import pytest
from trimesh.triangles import closest_point
from truths import rebaked, small_room

from invrender.evaluate.balls import BALL_LIGHTS, ball_errors, ball_normals, shade_balls
from invrender.evaluate.correspond import correspond
from invrender.evaluate.maps import ball_subset, compress, kg_mse, kg_mse_outside_sun, map_errors, sun_errors
from invrender.scene.atlas import AtlasTexels
from invrender.scene.cubemap import cube_texel_solid_angles
from invrender.scene.types import ATLAS_MAPS, Maps, Mesh


@pytest.fixture(scope="module")
def truth_and_copy():
    truth = small_room()
    copy, texels = rebaked(truth)
    return truth, copy, texels, correspond(texels, truth.mesh, truth.maps.atlas_shape, recovered_mesh=copy.mesh)


def with_maps(maps: Maps, **changed) -> Maps:
    return Maps(**{name: changed.get(name, getattr(maps, name)) for name in (*ATLAS_MAPS, "kg")})


def test_the_truth_on_another_mesh_and_atlas_scores_near_zero(truth_and_copy):
    truth, copy, texels, corr = truth_and_copy
    assert copy.maps.atlas_shape != truth.maps.atlas_shape and len(copy.mesh.faces) == 4 * len(truth.mesh.faces)
    assert corr.distance.max() < 1e-6  # the same surface
    same = map_errors(copy.maps, truth.maps, corr)
    perturbed = map_errors(with_maps(copy.maps, kd=copy.maps.kd + 0.1, ke=copy.maps.ke * 1.1), truth.maps, corr)
    print(same["map_mse"], same["material_mse"], perturbed["material_mse"], perturbed["light_maps_mse"])
    assert same["light_maps_mse"] < 1e-5 and same["material_mse"] < 1e-5
    assert all(value < 1e-4 for value in same["map_mse"].values()), same["map_mse"]
    assert perturbed["material_mse"] > 300 * same["material_mse"] and perturbed["material_mse"] > 1e-3
    assert perturbed["light_maps_mse_linear"] > 1e-3 and perturbed["light_maps_mse"] > 100 * same["light_maps_mse"]
    # kd + 0.1 everywhere: MSE 0.1^2, up to the ~1e-5 of resampling between the two atlases
    assert perturbed["map_mse"]["kd"] == pytest.approx(0.01, abs=3e-4)
    assert perturbed["map_mse"]["ks"] == same["map_mse"]["ks"]
    # the lamps' emission: all of it on the same surface, 1.1 x with ke 10 % up
    assert same["emitted_power_ratio"] == pytest.approx(1.0, abs=1e-3)
    assert perturbed["emitted_power_ratio"] == pytest.approx(1.1, abs=1e-3)


def test_the_constant_guess_is_the_truths_surface_mean_scored_the_same_way(truth_and_copy):
    """Each map set to the truth's mean over the covered texels scores exactly what the report
    calls the constant guess; kd's MSE is then the truth's variance on the surface."""
    truth, copy, texels, corr = truth_and_copy
    guess = map_errors(copy.maps, truth.maps, corr)["constant_guess"]
    true = {name: corr.truth_values(getattr(truth.maps, name)) for name in ATLAS_MAPS}
    constant = {name: np.zeros_like(getattr(copy.maps, name)) for name in ATLAS_MAPS}
    for name in ATLAS_MAPS:
        constant[name][corr.mask] = true[name].mean(axis=0)
    sky = np.average(
        truth.maps.kg.reshape(-1, 3),
        axis=0,
        weights=np.broadcast_to(cube_texel_solid_angles(truth.maps.kg.shape[1]), truth.maps.kg.shape[:3]).reshape(-1),
    )
    scored = map_errors(
        with_maps(copy.maps, **constant, kg=np.broadcast_to(sky, truth.maps.kg.shape)), truth.maps, corr
    )
    assert scored["material_mse"] == pytest.approx(guess["material_mse"], rel=1e-4)  # float32 maps
    assert scored["light_maps_mse"] == pytest.approx(guess["light_maps_mse"], rel=1e-4)
    assert guess["map_mse"]["kd"] == pytest.approx(true["kd"].var(axis=0).mean(), rel=1e-4)
    assert guess["material_mse"] > 10 * map_errors(copy.maps, truth.maps, corr)["material_mse"] + 1e-4


def test_a_light_perturbation_moves_the_light_maps_mse_by_its_mean(truth_and_copy):
    truth, copy, texels, corr = truth_and_copy
    kw = copy.maps.kw + 0.3  # kw MSE 0.09: the light maps MSE (mean of ke, kw, kg) rises by 0.03
    errors = map_errors(with_maps(copy.maps, kw=kw, kg=copy.maps.kg + 0.2), truth.maps, corr)
    assert errors["map_mse"]["kw"] == pytest.approx(0.09, abs=1e-3)
    assert errors["map_mse"]["kg"] == pytest.approx(0.04, rel=1e-6)
    assert errors["light_maps_mse_linear"] == pytest.approx((errors["map_mse"]["ke"] + 0.09 + 0.04) / 3, abs=1e-3)
    # on the compressed scale x / (1 + x): kw as it is, kg's shift of 0.2 shrunk where the sky is bright
    kg = kg_mse(compress(copy.maps.kg + 0.2), compress(truth.maps.kg))
    assert 0 < kg < 0.04
    compressed = errors["light_map_mse_compressed"]
    assert compressed["kw"] == errors["map_mse"]["kw"] and compressed["kg"] == pytest.approx(kg, rel=1e-9)
    assert errors["light_maps_mse"] == pytest.approx((compressed["ke"] + compressed["kw"] + kg) / 3, rel=1e-9)


def test_the_nearest_point_search_is_exact(truth_and_copy):
    truth = truth_and_copy[0]
    rng = np.random.default_rng(0)
    positions = np.asarray(truth.mesh.positions, np.float64)
    faces = np.asarray(truth.mesh.faces)
    # points off the surface by up to 15 cm in every direction, so that nearest triangles vary
    picked = rng.integers(0, len(faces), 300)
    points = positions[faces[picked]].mean(axis=1) + rng.normal(0, 0.08, (300, 3))
    points = points.astype(np.float32).astype(np.float64)  # as atlas.npz stores them
    texels = fake_texels(points, rng.normal(size=(300, 3)))
    corr = correspond(texels, truth.mesh, truth.maps.atlas_shape, side_margin=0.0)
    triangles = positions[faces]
    brute = [np.linalg.norm(closest_point(triangles, np.repeat(p[None], len(faces), 0)) - p, axis=1) for p in points]
    assert np.allclose(corr.distance, [b.min() for b in brute], rtol=0, atol=1e-12)
    assert (corr.distance > 0.02).sum() > 100  # most points are off the surface, where candidates matter


def fake_texels(points, normals) -> AtlasTexels:
    """A one-row 'atlas' whose texels sit at the given points with the given normals."""
    n = len(points)
    normals = np.asarray(normals, np.float64)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return AtlasTexels(
        triangle=np.zeros((1, n), np.int32),
        barycentric=np.zeros((1, n, 3), np.float32),
        position=np.asarray(points, np.float32)[None],
        normal=normals.astype(np.float32)[None],
        mask=np.ones((1, n), bool),
    )


def test_a_thin_two_sided_slab_is_read_from_the_texels_side():
    # A 1 m slab 2 cm thick: its top (y = 0.02, facing up) red in the atlas' left half, its
    # bottom (y = 0, facing down) blue in the right half.
    corners = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], np.float32)
    top, bottom = corners + [0, 0.02, 0], corners
    positions = np.concatenate([top, bottom])
    faces = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7]], np.int32)  # top up, bottom down
    uvs = np.array([[0.05, 0.05], [0.45, 0.05], [0.45, 0.95], [0.05, 0.95]] * 2, np.float32)
    uvs[4:, 0] += 0.5
    mesh = Mesh(positions, faces, uvs)
    kd = np.zeros((8, 8, 3), np.float32)
    kd[:, :4] = (1, 0, 0)
    kd[:, 4:] = (0, 0, 1)
    # texels 1.5 cm up facing down (nearer the top, on the bottom's side), and 0.5 cm up facing up
    points = np.array([[0.3, 0.015, 0.4], [0.7, 0.005, 0.6]])
    texels = fake_texels(points, [[0, -1, 0], [0, 1, 0]])
    corr = correspond(texels, mesh, kd.shape[:2])
    assert corr.truth_values(kd).tolist() == [[0, 0, 1], [1, 0, 0]]
    assert corr.facing_preferred.tolist() == [True, True]
    nearest_only = correspond(texels, mesh, kd.shape[:2], side_margin=0.0)
    assert nearest_only.truth_values(kd).tolist() == [[1, 0, 0], [0, 0, 1]]  # what the side rule prevents


def test_kg_is_compared_over_directions_across_cube_sizes():
    rng = np.random.default_rng(1)
    coarse = rng.random((6, 4, 4, 3)).astype(np.float32)
    fine = coarse.repeat(2, axis=1).repeat(2, axis=2)  # the same radiance on an 8^2 cube
    assert kg_mse(coarse, fine) == 0.0
    assert kg_mse(fine + 0.1, coarse) == pytest.approx(0.01, rel=1e-5)
    # a difference on one face only: that face is a sixth of the sphere
    one_face = fine.copy()
    one_face[2] += 0.3
    assert kg_mse(one_face, coarse) == pytest.approx(0.09 / 6, rel=1e-5)
    assert 6 * cube_texel_solid_angles(8).sum() == pytest.approx(4 * np.pi)


def test_shading_balls_follow_lamberts_law_for_a_diffuse_material():
    kd = np.array([[0.3, 0.2, 0.1]])
    ball = shade_balls(kd, np.zeros((1, 3)), np.array([0.2]))[0]
    normals = ball_normals()
    irradiance = sum(e * np.maximum(normals @ (np.array(d) / np.linalg.norm(d)), 0) for d, e in BALL_LIGHTS)
    assert np.allclose(ball, np.clip(kd / np.pi * irradiance[:, None], 0, 1), atol=1e-12)
    assert len(normals) == 208  # the 16 x 16 pixels inside the outline
    # identical materials: no error; a specular lobe: an error in the highlight only
    same = (kd, np.zeros((1, 3)), np.array([0.2]))
    shiny = (kd, np.full((1, 3), 0.5), np.array([0.01]))
    assert ball_errors(same, same)[0] == 0.0 and ball_errors(shiny, same)[0] > 1e-3


def test_ball_texels_are_taken_at_an_even_stride():
    assert ball_subset(10, 4).tolist() == [0, 3, 6, 9]
    assert ball_subset(3, 4).tolist() == [0, 1, 2]
    assert ball_subset(5, None).tolist() == [0, 1, 2, 3, 4]


def test_a_texel_on_an_edge_shared_with_another_material_reads_its_own_side():
    # a ceiling quad (faces 0, 1, kd red) beside a lamp quad (faces 2, 3, kd blue), coplanar,
    # sharing the edge x = 1; the texel sits exactly on that edge but belongs to the lamp
    ceiling = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], np.float32)
    positions = np.concatenate([ceiling, ceiling + [1, 0, 0]])
    faces = np.array([[0, 2, 1], [0, 3, 2], [4, 6, 5], [4, 7, 6]], np.int32)
    uvs = np.array([[0.05, 0.05], [0.45, 0.05], [0.45, 0.95], [0.05, 0.95]] * 2, np.float32)
    uvs[4:, 0] += 0.5
    mesh = Mesh(positions, faces, uvs)
    kd = np.zeros((8, 8, 3), np.float32)
    kd[:, :4], kd[:, 4:] = (1, 0, 0), (0, 0, 1)
    texels = fake_texels([[1.0, 0.0, 0.5]], [[0, 1, 0]])
    texels.triangle[:] = 3  # the lamp's face whose edge x = 1 holds the point
    assert correspond(texels, mesh, kd.shape[:2]).truth_values(kd).tolist() == [[1, 0, 0]]  # a tie: lowest id
    own = correspond(texels, mesh, kd.shape[:2], recovered_mesh=mesh)
    assert own.truth_values(kd).tolist() == [[0, 0, 1]] and own.distance.tolist() == [0.0]


def test_the_sky_outside_the_suns_disc_is_scored_without_the_sun():
    """A uniform sky of 1 with a sun of 150 in one texel: a recovery that misses the sun but has
    the sky right scores 0 outside the disc (and far from 0 with it); 1.2 everywhere else, 0.04."""
    n = 8
    truth = np.ones((6, n, n, 3))
    truth[2, 3, 4] = 150.0
    missed_sun = np.ones_like(truth)
    assert kg_mse(missed_sun, truth) > 1.0
    assert kg_mse_outside_sun(missed_sun, truth) == pytest.approx(0.0)
    assert kg_mse_outside_sun(np.full_like(truth, 1.2), truth) == pytest.approx(0.04)
    assert kg_mse_outside_sun(np.zeros_like(truth), np.zeros_like(truth)) == 0.0  # no sky, no sun
    beside = np.ones_like(truth)
    beside[2, 3, 5] = 150.0  # the sun a texel off: the sky is still right, the sun scored apart
    assert kg_mse_outside_sun(beside, truth) == pytest.approx(0.0)
    areas = cube_texel_solid_angles(n)
    assert sun_errors(beside, truth)["power_ratio"] == pytest.approx(areas[3, 5] / areas[3, 4])
    assert 5.0 < sun_errors(beside, truth)["direction_error_deg"] < 15.0  # a texel of a 8 x 8 face
    assert sun_errors(missed_sun, truth) == {"power_ratio": 0.0, "direction_error_deg": None}
    assert sun_errors(truth, truth)["direction_error_deg"] == pytest.approx(0.0, abs=1e-3)
    assert sun_errors(truth, np.ones_like(truth)) is None
