"""Several wires at once (3.7.3): instances, association by reprojection, one fit each."""

import numpy as np

from geometry.shapes import distance_to_polyline_m
from mapping.catenary.instances import reconstruct_wires, track_wires, wire_instances
from mapping.catenary.model import catenary_points_ned_m, sample_abscissae_m
from mapping.catenary.params import CatenaryParams
from mapping.catenary.sim import approach_scenario, cnn_like_mask, curve_error_m, sim_camera

CAMERA = sim_camera()
PARAMS = CatenaryParams()
# Two parallel wires 3 m apart in height (a power line and the earth wire above it).
THETAS = np.array([[0.0, 0.0, -10.0, 0.3, 30.0], [0.5, 0.2, -13.0, 0.3, 60.0]])


def test_instances_merge_broken_wires_and_drop_speckle() -> None:
    mask = np.zeros((50, 90), bool)
    mask[10, 5:40] = True
    mask[10, 46:85] = True  # the same wire after a gap of missed detections
    mask[30:32, 5:85] = True  # a second, parallel wire
    mask[45, 1:4] = True  # speckle
    mask[40:47, 60:67] = True  # a blob: enough pixels, but no wire
    instances = wire_instances(mask, 10, 20.0, 3.0)
    assert sorted(int(m.sum()) for m in instances) == [74, 160]


def test_parallel_wires_are_tracked_and_fitted_separately() -> None:
    sim = approach_scenario(np.random.default_rng(0), CAMERA, THETAS, 10, PARAMS.half_span_m)
    instances = [
        wire_instances(
            m, PARAMS.instance_min_pixels, PARAMS.instance_min_length_px, PARAMS.merge_gate_px
        )
        for m in sim.masks
    ]
    tracks = track_wires(CAMERA, sim.poses, instances, PARAMS, 4.0, 20.0)
    assert sorted(len(t.keyframe_indices) for t in tracks) == [10, 10]

    fits = reconstruct_wires(CAMERA, sim.poses, sim.masks, sim.stamps_s, PARAMS, 4.0, 20.0)
    assert len(fits) == 2
    errors = np.array(
        [[curve_error_m(f.theta, t, PARAMS.half_span_m) for t in THETAS] for f in fits]
    )
    # Each fit explains one wire (not the valley between them) and the two are different.
    assert sorted(np.argmin(errors, axis=1).tolist()) == [0, 1]
    assert errors.min(axis=1).max() < 0.6  # head-on approach: depth is the weak direction
    for fit, truth in zip(fits, THETAS[np.argmin(errors, axis=1)], strict=True):
        assert fit.confident
        # ... and its uncertainty says so: the true wire lies within the 3-sigma band.
        dense = catenary_points_ned_m(truth, sample_abscissae_m(PARAMS.half_span_m, 400))
        distance, _, _ = distance_to_polyline_m(fit.points_ned_m, dense)
        assert np.all(distance <= 3.0 * fit.uncertainty.point_sigma_m)


def test_a_noisy_thick_segmentation_still_gives_one_calibrated_wire() -> None:
    # CNN-like masks: 4 px thick, three gaps of missed detections, false-positive blobs.
    rng = np.random.default_rng(11)
    theta = np.array([[0.0, 0.0, -10.0, 0.4, 25.0]])
    sim = approach_scenario(rng, CAMERA, theta, 12, PARAMS.half_span_m, 22.0, 14.0)
    masks = [cnn_like_mask(rng, m) for m in sim.masks]
    (clean,) = reconstruct_wires(CAMERA, sim.poses, sim.masks, sim.stamps_s, PARAMS, 4.0, 20.0)
    (fit,) = reconstruct_wires(CAMERA, sim.poses, masks, sim.stamps_s, PARAMS, 4.0, 20.0)
    assert clean.confident and fit.confident
    dense = catenary_points_ned_m(theta[0], sample_abscissae_m(PARAMS.half_span_m, 400))
    distance, _, _ = distance_to_polyline_m(fit.observed_points_ned_m, dense)
    assert distance.max() < 1.0
    # Noise costs accuracy, and the uncertainty says so: the wire stays inside 3 sigma.
    assert np.all(distance <= 3.0 * fit.uncertainty.point_sigma_m[fit.observed_span])
    assert fit.uncertainty.point_sigma_m.max() > clean.uncertainty.point_sigma_m.max()
