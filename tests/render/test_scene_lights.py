import numpy as np
import pytest

from gonio.errors import ParameterError
from gonio.render import Camera, Directional, Environment, PointLight, SphereLight
from gonio.render.lights import direction_to_latlong, latlong_to_direction, studio_environment
from gonio.render.scene import intersect_sphere


def test_orthographic_hits_cover_the_disk():
    n = 64
    hits = intersect_sphere(n)
    # Pixel centres inside the unit disk: close to pi/4 of the image.
    assert abs(hits.count / n**2 - np.pi / 4) < 0.02
    np.testing.assert_allclose(np.linalg.norm(hits.position, axis=-1), 1.0, atol=1e-5)
    # Orthographic: the view direction is +z in world; wo is its local expression.
    world_wo = np.einsum("pji,pj->pi", hits.frame, hits.wo)
    np.testing.assert_allclose(world_wo, np.tile([0.0, 0.0, 1.0], (hits.count, 1)), atol=1e-5)
    assert np.all(hits.wo[:, 2] > 0)


def test_image_orientation_and_center_frame():
    hits = intersect_sphere(65)
    rows, cols = np.divmod(hits.index, 65)
    # Row 0 is the top (y > 0); column 0 the left (x < 0).
    top = hits.position[rows == rows.min()]
    assert np.all(top[:, 1] > 0.9)
    left = hits.position[cols == cols.min()]
    assert np.all(left[:, 0] < -0.9)
    centre = (rows == 32) & (cols == 32)
    np.testing.assert_allclose(hits.frame[centre][0], np.eye(3), atol=1e-6)
    np.testing.assert_allclose(hits.wo[centre][0], [0, 0, 1], atol=1e-6)


def test_frames_are_orthonormal():
    hits = intersect_sphere(32, Camera.perspective(distance=3.0))
    f = hits.frame.astype(np.float64)
    eye = np.einsum("pij,pkj->pik", f, f)
    np.testing.assert_allclose(eye, np.broadcast_to(np.eye(3), eye.shape), atol=1e-5)
    np.testing.assert_allclose(f[:, 2], hits.position, atol=1e-5)


def test_perspective_wo_points_to_the_camera():
    cam = Camera.perspective(distance=3.0)
    hits = intersect_sphere(32, cam)
    world_wo = np.einsum("pji,pj->pi", hits.frame, hits.wo)
    to_cam = np.array([0, 0, 3.0]) - hits.position
    to_cam /= np.linalg.norm(to_cam, axis=-1, keepdims=True)
    np.testing.assert_allclose(world_wo, to_cam, atol=1e-5)


def test_hits_are_shared_between_renders_of_one_image_and_read_only():
    a = intersect_sphere(24)
    assert intersect_sphere((24, 24), Camera()) is a  # the same image: traced once
    assert intersect_sphere(24, Camera.perspective(distance=3.0)) is not a
    assert intersect_sphere(25) is not a
    for arr in (a.index, a.position, a.frame, a.wo):
        with pytest.raises(ValueError, match="read-only"):
            arr[0] = 0


@pytest.mark.parametrize(
    "make",
    [
        lambda: Camera("fisheye"),
        lambda: Camera.perspective(distance=0.5),
        lambda: intersect_sphere(0),
        lambda: intersect_sphere("big"),
        lambda: Directional((0, 0, 0)),
        lambda: Directional((0, 0, 1), irradiance=-1),
        lambda: PointLight((0, 0, 0.5)),
        lambda: SphereLight((0, 0, 1.5), 1.0),
        lambda: Environment(np.full((4, 8, 3), np.nan)),
        lambda: Environment(np.zeros((4, 8))).importance(),
    ],
)
def test_bad_input_raises_parameter_error(make):
    with pytest.raises(ParameterError):
        make()


def test_latlong_roundtrip_and_orientation():
    rng = np.random.default_rng(0)
    xy = rng.random((1000, 2)) * 0.98 + 0.01
    w = np.asarray(latlong_to_direction(xy))
    np.testing.assert_allclose(np.asarray(direction_to_latlong(w)), xy, atol=1e-6)
    np.testing.assert_allclose(
        np.asarray(latlong_to_direction(np.array([0.5, 0.5]))), [0, 0, -1], atol=1e-7
    )
    np.testing.assert_allclose(
        np.asarray(latlong_to_direction(np.array([0.75, 0.5]))), [1, 0, 0], atol=1e-7
    )


def _sphere_points(n=256, seed=1):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return (v / np.linalg.norm(v, axis=-1, keepdims=True)).astype(np.float32)


@pytest.mark.parametrize("light", ["sphere", "env"])
def test_area_light_pdf_matches_sampling(light):
    if light == "sphere":
        lt = SphereLight((2.0, 1.0, 2.5), 0.4, radiance=3.0)
    else:
        lt = Environment("studio").importance()
    p = _sphere_points(64)
    u = np.random.default_rng(2).random((64, 2000, 2)).astype(np.float32)
    pp = np.broadcast_to(p[:, None, :], (64, 2000, 3))
    s = lt.sample(pp, u)
    ok = np.asarray(s.pdf) > 0
    assert ok.mean() > 0.999
    # Samples exactly on a cell or cone boundary may round to the neighbour: allow 1 in 10^4.
    pdf_again = np.asarray(lt.pdf(pp, s.wi))[ok]
    assert np.mean(~np.isclose(pdf_again, np.asarray(s.pdf)[ok], rtol=2e-3)) < 1e-4
    value_again = np.asarray(lt.radiance(pp, s.wi))[ok]
    assert np.mean(~np.isclose(value_again, np.asarray(s.value)[ok], rtol=1e-5)) < 1e-4
    if light == "sphere":
        # E[1/pdf] is the solid angle of the light (exact for uniform cone sampling).
        d = np.linalg.norm(np.array([2.0, 1.0, 2.5]) - p, axis=-1)
        omega = 2 * np.pi * (1 - np.sqrt(1 - (0.4 / d) ** 2))
        np.testing.assert_allclose(np.mean(1 / np.asarray(s.pdf), axis=1), omega, rtol=1e-4)


def test_environment_pdf_integrates_to_one():
    env = Environment("studio").importance()
    # Midpoint quadrature on a grid finer than the map.
    h, w = 512, 1024
    xy = np.stack(np.meshgrid((np.arange(w) + 0.5) / w, (np.arange(h) + 0.5) / h), -1)
    d = np.asarray(latlong_to_direction(xy.astype(np.float32)))
    pdf = np.asarray(env.pdf(d, d))
    d_omega = (2 * np.pi / w) * (np.pi / h) * np.sin(np.pi * xy[..., 1])
    assert abs(np.sum(pdf * d_omega) - 1.0) < 2e-3


def test_studio_environment_has_soft_boxes_on_dim_background():
    img = studio_environment()
    assert img.shape == (128, 256, 3) and img.dtype == np.float32
    assert np.all(img > 0)
    assert img.max() > 5.0  # a bright key light
    assert np.median(img) < 0.2  # on a dim gradient
    # Brighter above than below.
    assert img[:20].mean() > img[-20:].mean()


def test_channels_subset_of_lights():
    e = Environment("studio").with_channels(np.array([2]))
    assert e.channels == 1
    np.testing.assert_allclose(np.asarray(e.image[..., 0]), studio_environment()[..., 2])
    d = Directional((0, 0, 1), [1.0, 2.0, 3.0]).with_channels(np.array([1]))
    np.testing.assert_allclose(d.irradiance, [2.0])


def test_environment_from_exr_file(tmp_path):
    from gonio.render.output import write_exr

    img = studio_environment(16, 32)
    p = write_exr(tmp_path / "env.exr", img)
    env = Environment(p, scale=2.0)
    np.testing.assert_allclose(np.asarray(env.image), 2 * img, rtol=1e-6)
    with pytest.raises(ParameterError):
        Environment(tmp_path / "missing.exr")


def test_latlong_inverse_in_float32_matches_float64_trigonometry():
    # direction_to_latlong uses a polynomial atan2 in float32; it must agree with arccos and
    # arctan2 evaluated in float64 on the same float32 directions to a few float32 ulps
    rng = np.random.default_rng(11)
    w = rng.normal(size=(20000, 3))
    w = (w / np.linalg.norm(w, axis=-1, keepdims=True)).astype(np.float32)
    got = np.asarray(direction_to_latlong(w))
    assert got.dtype == np.float32
    w64 = w.astype(np.float64)
    ref_x = np.arctan2(w64[:, 0], -w64[:, 2]) / (2 * np.pi) + 0.5
    ref_y = np.arccos(np.clip(w64[:, 1], -1, 1)) / np.pi
    np.testing.assert_allclose(got[:, 0], ref_x, atol=3e-7)
    np.testing.assert_allclose(got[:, 1], ref_y, atol=3e-7)


def test_latlong_pixel_directions_are_latlong_to_direction_at_pixel_centres():
    from gonio.render.lights import latlong_pixel_directions

    h, w = 9, 14
    x, y = np.meshgrid((np.arange(w) + 0.5) / w, (np.arange(h) + 0.5) / h)
    expect = np.asarray(latlong_to_direction(np.stack([x, y], -1).astype(np.float64)))
    got = latlong_pixel_directions(h, w)
    assert got.shape == (h, w, 3) and got.dtype == np.float64
    np.testing.assert_allclose(got, expect, atol=1e-12)


def test_studio_environment_is_built_without_tracing_jax():
    """A second process builds the studio on every start: NumPy only (tracing and compiling
    its JAX ops one by one cost 0.5 s of CPU with a warm compilation cache)."""
    from jax import monitoring

    traced = []

    def listener(event, duration, **kw):
        if event == "/jax/core/compile/jaxpr_trace_duration":
            traced.append(event)

    monitoring.register_event_duration_secs_listener(listener)
    try:
        img = studio_environment(32, 64)
    finally:
        monitoring.unregister_event_duration_listener(listener)
    assert img.shape == (32, 64, 3) and not traced
