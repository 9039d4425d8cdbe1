"""The compiled query kernel against the numpy definition of Table 4.1 and eq. 4.4-4.5."""

import numpy as np

from mapping.droan.occupancy import (
    confidence,
    confidence_odds,
    occupancy_measure,
    stereo_occupancy_cost,
    summed_costs,
    wire_occupancy_cost,
)

H, W, NODES = 12, 16, 5
SIGMA, FREE, OCCLUDED, WIRE_FREE, BF, NEAR, FAR = 0.23, 0.5, 0.25, 1.5, 40.0, 1e-3, 30.0
WIRE_NEAR = 6.0  # px: the slab fronts are drawn from [2, 10]


def random_graph(rng: np.random.Generator):
    """Node images with unknown, free, banded and wire pixels, and cameras looking north."""
    images = np.full((NODES * H * W, 8), -1.0, np.float32)
    known = rng.random(len(images)) < 0.8
    front = rng.uniform(0.0, 8.0, len(images))
    back = front - rng.uniform(0.0, 3.0, len(images))
    own_front = back - rng.uniform(0.0, 2.0, len(images))
    own_back = own_front - rng.uniform(0.0, 2.0, len(images))
    for channel, values in enumerate((front, back, own_front, own_back)):
        images[known, channel] = values[known]
    wire_known = rng.random(len(images)) < 0.7
    wire_front = np.where(rng.random(len(images)) < 0.3, rng.uniform(2.0, 10.0, len(images)), 0)
    images[wire_known, 4] = wire_front[wire_known]
    images[wire_known, 5] = np.maximum(wire_front[wire_known] - 8.0, 0.0)
    possible = wire_known & (rng.random(len(images)) < 0.5)  # wire-or-undecided slabs
    images[possible, 6] = np.maximum(wire_front[possible], rng.uniform(2.0, 10.0, possible.sum()))
    images[possible, 7] = np.maximum(images[possible, 6] - 8.0, 0.0)
    intrinsics = np.array([[10.0, 0.0, W / 2], [0.0, 10.0, H / 2], [0.0, 0.0, 1.0]])
    north = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])  # camera from NED
    projection = np.stack([intrinsics @ north] * NODES).astype(np.float32)
    offset = np.stack(
        [intrinsics @ (-north @ np.array([-i, 0.3 * i, 0.0])) for i in range(NODES)]
    ).astype(np.float32)
    return images, projection, offset


def numpy_reference(points, projection, offset, slots, images):
    """The same query from the elementwise numpy definitions (unknown pixels cost 0)."""
    homogeneous = projection[slots] @ points.T + offset[slots][:, :, None]
    z = homogeneous[:, 2]
    inv_z = 1.0 / np.maximum(z, NEAR)
    u, v = homogeneous[:, 0] * inv_z + 0.5, homogeneous[:, 1] * inv_z + 0.5
    in_view = (z > NEAR) & (z <= FAR) & (u >= 0) & (u < W) & (v >= 0) & (v < H)
    rows = (slots[:, None] * H + np.clip(v, 0, H - 1).astype(int)) * W
    rows += np.clip(u, 0, W - 1).astype(int)
    cells = np.where(in_view[..., None], images[rows], -1.0).astype(np.float32)
    d = (BF * inv_z).astype(np.float32)
    stereo, observed = stereo_occupancy_cost(
        d, *np.moveaxis(cells[..., :4], -1, 0), SIGMA, FREE, OCCLUDED
    )
    wire = wire_occupancy_cost(
        d, cells[..., 4], cells[..., 5], WIRE_FREE, WIRE_NEAR, cells[..., 6], cells[..., 7]
    )
    return occupancy_measure(stereo), occupancy_measure(wire), observed.any(axis=0)


def test_the_kernel_answers_as_the_numpy_definition() -> None:
    rng = np.random.default_rng(7)
    images, projection, offset = random_graph(rng)
    points = rng.uniform([-3, -6, -5], [35, 6, 5], size=(5000, 3)).astype(np.float32)
    points[:50, 0] = 0.0  # on node 0's camera plane: depth 0 must not poison the sums
    slots = np.array([0, 2, 3, 4])
    f32 = np.float32
    stereo, wire, seen = summed_costs(
        points, projection, offset, slots, images, H, W,
        f32(BF), f32(NEAR), f32(FAR), f32(SIGMA), f32(FREE), f32(OCCLUDED),
        f32(WIRE_FREE), f32(WIRE_NEAR),
    )  # fmt: skip
    expected_stereo, expected_wire, expected_seen = numpy_reference(
        points, projection, offset, slots, images
    )
    occupancy = np.maximum(stereo, wire)
    assert 0.1 < seen.mean() < 0.95 and 0.05 < (occupancy > 1.0).mean() < 0.95
    assert (wire >= 1.0).mean() > 0.05 and ((wire >= 1.0) & (stereo < 1.0)).any()
    assert np.isfinite(occupancy).all()
    np.testing.assert_array_equal(seen, expected_seen)
    np.testing.assert_allclose(stereo, expected_stereo, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(wire, expected_wire, rtol=1e-5, atol=1e-4)


def test_the_occupied_cost_is_the_odds_of_the_eq_4_4_confidence() -> None:
    d = np.array([0.1, 0.23, 0.5, 2.0, 40.0], np.float32)
    c = confidence(d, SIGMA)
    np.testing.assert_allclose(c, np.clip((d - SIGMA) / d, 0, 1), rtol=1e-6)
    np.testing.assert_allclose(confidence_odds(d, SIGMA), c / (1 - c), rtol=1e-5)
    assert confidence_odds(d, SIGMA)[:2].tolist() == [0.0, 0.0]  # d <= sigma: no evidence
