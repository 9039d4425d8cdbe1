"""The trajectory library of thesis 4.5 / Fig. 4.8: feasibility, content, size, file, plot."""

from pathlib import Path

import numpy as np
import pytest

from companion.cli.planning import load_library, plot_library, save_library
from planning.library import TrajectoryLibrary, generate_library
from planning.params import PlanningParams

PARAMS = PlanningParams()
TOL = 1.03  # finite differences of 0.2 s samples projected on the path frame


@pytest.fixture(scope="module")
def library() -> TrajectoryLibrary:
    return generate_library(PARAMS)


def _path_frame(x: np.ndarray, along: np.ndarray) -> np.ndarray:
    """(..., 3) vectors as (tangential, lateral, vertical) of the horizontal `along` (..., 3)."""
    heading = np.arctan2(along[..., 1], along[..., 0])
    c, s = np.cos(heading), np.sin(heading)
    return np.stack([c * x[..., 0] + s * x[..., 1], -s * x[..., 0] + c * x[..., 1], x[..., 2]], -1)


def test_every_trajectory_respects_the_vehicle_limits(library) -> None:
    times = np.concatenate([[0.0], library.times_s])
    dt = np.diff(times)[None, None, :, None]
    start = np.zeros((*library.positions_m.shape[:2], 1, 3))
    start[..., 0] = library.initial_speeds_mps[:, None, None]
    v = np.concatenate([start, library.velocities_mps], axis=2)  # (S, K, M + 1, 3)
    p = np.concatenate([np.zeros_like(start), library.positions_m], axis=2)

    horizontal = np.linalg.norm(v[..., :2], axis=-1)
    assert horizontal.max() <= PARAMS.max_speed_mps + 1e-9
    assert np.abs(v[..., 2]).max() <= PARAMS.max_vertical_speed_mps + 1e-9
    # positions integrate the velocities (trapezoid over a waypoint interval)
    np.testing.assert_allclose(
        np.diff(p, axis=2), 0.5 * (v[:, :, 1:] + v[:, :, :-1]) * dt, atol=0.02
    )

    accel = np.diff(v, axis=2) / dt
    accel_path = _path_frame(accel, 0.5 * (v[:, :, 1:] + v[:, :, :-1]))
    assert np.abs(accel_path).max() <= PARAMS.max_accel_mps2 * TOL
    jerk = np.diff(accel, axis=2) / dt[:, :, 1:]
    jerk_path = _path_frame(jerk, v[:, :, 1:-1])
    assert np.abs(jerk_path).max() <= PARAMS.max_jerk_mps3 * TOL

    heading = np.arctan2(v[..., 1], v[..., 0])
    turn = np.angle(np.exp(1j * np.diff(heading, axis=2))) / dt[..., 0]
    moving = (horizontal[..., 1:] > 0.3) & (horizontal[..., :-1] > 0.3)
    assert np.abs(turn[moving]).max() <= PARAMS.max_yaw_rate_radps * TOL
    # lateral acceleration v * yaw rate stays within the acceleration limit too
    lateral = np.abs(turn) * 0.5 * (horizontal[..., 1:] + horizontal[..., :-1])
    assert lateral[moving].max() <= PARAMS.max_accel_mps2 * TOL


def test_the_library_holds_the_manoeuvres_of_fig_4_8(library) -> None:
    labels = library.labels
    assert library.size == PARAMS.library_size == 71
    for name in ("straight", "left-1", "left-3", "right-2", "climb-2", "descend-1"):
        assert name in labels
    assert "left-2 climb-1" in labels and "right-3 descend-2" in labels
    assert "straight v1.0" in labels and labels[library.stop_index] == "stop"
    assert len(library.times_s) == PARAMS.waypoints
    assert library.times_s[-1] == pytest.approx(PARAMS.horizon_s)

    cruise = library.bin_for_speed(PARAMS.max_speed_mps)
    end = library.positions_m[cruise, :, -1]
    final_heading = np.arctan2(*library.velocities_mps[cruise, :, -1, 1::-1].T)

    def at(name: str) -> int:
        return labels.index(name)

    np.testing.assert_allclose(
        end[at("straight")], [PARAMS.max_speed_mps * 4.0 - 0.05, 0, 0], atol=0.3
    )
    assert end[at("left-1"), 1] < -0.5 and end[at("right-1"), 1] > 0.5  # y right
    assert end[at("left-1"), 1] == pytest.approx(-end[at("right-1"), 1])
    # curvature grows with the level
    turns = [abs(final_heading[at(f"right-{i}")]) for i in (1, 2, 3)]
    assert turns[0] < turns[1] < turns[2] <= PARAMS.max_heading_change_rad + 1e-6
    assert turns[0] > 0.2
    assert end[at("climb-2"), 2] < end[at("climb-1"), 2] < -0.5  # NED: up is negative
    assert end[at("descend-2"), 2] > end[at("descend-1"), 2] > 0.5
    combo = end[at("left-2 climb-1")]
    assert combo[1] < -0.5 and combo[2] < -0.5
    # the stop brakes from cruise to standstill within the horizon
    stop = library.velocities_mps[cruise, library.stop_index]
    assert np.linalg.norm(stop[-1]) < 1e-6
    assert np.all(np.diff(np.linalg.norm(stop, axis=-1)) <= 1e-9)
    # the slower manoeuvres end half as far
    assert end[at("straight v1.0"), 0] == pytest.approx(0.5 * end[at("straight"), 0], rel=0.1)


@pytest.mark.parametrize(("turn", "climb", "speed", "size"), [(1, 0, 1, 4), (4, 3, 3, 190)])
def test_the_size_is_configurable(turn: int, climb: int, speed: int, size: int) -> None:
    params = PARAMS.model_copy(
        update={"turn_levels": turn, "climb_levels": climb, "speed_levels": speed, "waypoints": 10}
    )
    library = generate_library(params)
    assert library.size == params.library_size == size
    assert library.positions_m.shape == (PARAMS.speed_bins, size, 10, 3)
    assert len(set(library.labels)) == size


def test_save_and_load_round_trip(library, tmp_path: Path) -> None:
    path = tmp_path / "library.npz"
    save_library(library, path)
    loaded = load_library(path)
    assert loaded.labels == library.labels and loaded.stop_index == library.stop_index
    for key, value in library.as_arrays().items():
        np.testing.assert_array_equal(loaded.as_arrays()[key], value)
    arrays = library.as_arrays()
    arrays["positions_m"] = arrays["positions_m"][:, :-1]
    with pytest.raises(ValueError, match="shape"):
        TrajectoryLibrary.from_arrays(arrays)


def test_plot_writes_a_png(library, tmp_path: Path) -> None:
    path = tmp_path / "library.png"
    plot_library(library, 2.0, path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert path.stat().st_size > 20_000


def test_to_world_rotates_by_the_heading(library) -> None:
    positions, velocities = library.to_world(8, np.array([1.0, 2.0, -3.0]), np.pi / 2)
    straight = library.labels.index("straight")
    # heading east: the straight runs along +east, "right" turns towards south (+x NED negative)
    assert positions[straight, -1, 1] - 2.0 == pytest.approx(
        library.positions_m[8, straight, -1, 0]
    )
    assert positions[straight, -1, 0] == pytest.approx(1.0, abs=1e-9)
    right = library.labels.index("right-1")
    assert positions[right, -1, 0] < 1.0 - 0.5
    np.testing.assert_allclose(
        np.linalg.norm(velocities, axis=-1), np.linalg.norm(library.velocities_mps[8], axis=-1)
    )
