"""`wireavoid` commands of the catenary domain: `wireavoid bench catenary`."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer

SUCCESS_TOLERANCE_M = 0.25
CONVERGED_COST_RATIO = 1.05
LONG_WIRE_M = 40.0


def _median(values: list[float]) -> float | None:
    """Median, or None for an empty list (JSON null)."""
    import numpy as np

    return float(np.median(values)) if values else None


def _inside_tube_band(fit: Any, scenario: Any, params: Any) -> bool:
    """True if the true wire lies within k sigma of every observed fitted sample (3.7.2)."""
    import numpy as np

    from geometry.shapes import distance_to_polyline_m
    from mapping.catenary.model import catenary_points_ned_m, sample_abscissae_m

    truth = catenary_points_ned_m(scenario.theta_true, sample_abscissae_m(params.half_span_m, 400))
    observed = fit.uncertainty.observed
    distance_m, _, _ = distance_to_polyline_m(fit.points_ned_m[observed], truth)
    band_m = params.tube_sigma_multiplier * fit.uncertainty.point_sigma_m[observed]
    return bool(np.all(distance_m <= band_m + 0.02))


def _scenario_cell(
    rng: Any,
    camera: Any,
    params: Any,
    placement: str,
    straight: bool,
    n_cameras: int,
    trials: int,
    depth_near_m: float,
    depth_far_m: float,
) -> dict[str, Any]:
    """Run `trials` simulated fits of one 3.4.1 scenario and summarise them."""
    import time

    import numpy as np

    from mapping.catenary.fit import fit_catenary, reconstruct_catenary
    from mapping.catenary.sim import (
        curve_error_m,
        frustum_initialisation,
        random_scenario,
        sag_error_m,
    )

    rows: dict[str, list[float]] = {
        k: []
        for k in (
            "fit_ms",
            "fit_cpu_ms",
            "dt_ms",
            "curve",
            "vertex",
            "sag",
            "ok",
            "conf",
            "bad",
            "rand_ok",
            "rand_converged",
            "rand_bad",
        )
    }
    for _ in range(trials):
        scenario = random_scenario(
            rng,
            camera,
            n_cameras,
            placement,
            straight,
            params.half_span_m,  # type: ignore[arg-type]
        )
        start = time.perf_counter()
        views = scenario.views(camera)
        rows["dt_ms"].append((time.perf_counter() - start) * 1e3 / n_cameras)
        start, start_cpu = time.perf_counter(), time.thread_time()
        fit = reconstruct_catenary(views, params, depth_near_m, depth_far_m)
        rows["fit_ms"].append((time.perf_counter() - start) * 1e3)
        rows["fit_cpu_ms"].append((time.thread_time() - start_cpu) * 1e3)
        error = curve_error_m(fit.theta, scenario.theta_true, params.half_span_m)
        ok = error <= SUCCESS_TOLERANCE_M
        rows["curve"].append(error)
        rows["vertex"].append(float(np.linalg.norm(fit.theta[:3] - scenario.theta_true[:3])))
        rows["sag"].append(sag_error_m(fit.theta, scenario.theta_true, params.half_span_m))
        rows["ok"].append(ok)
        rows["conf"].append(fit.confident)
        rows["bad"].append(fit.confident and not _inside_tube_band(fit, scenario, params))
        random_fit = fit_catenary(
            views, frustum_initialisation(rng, views, depth_near_m, depth_far_m), params
        )
        random_ok = (
            curve_error_m(random_fit.theta, scenario.theta_true, params.half_span_m)
            <= SUCCESS_TOLERANCE_M
        )
        rows["rand_ok"].append(random_ok)
        # Converged: at the truth, or in a minimum at least as deep as the data-seeded fit's
        # (with 2 avoidance views that minimum can be wrong, Fig. 3.10: the data's limit).
        rows["rand_converged"].append(
            random_ok or random_fit.cost <= CONVERGED_COST_RATIO * fit.cost
        )
        rows["rand_bad"].append(
            random_fit.confident and not _inside_tube_band(random_fit, scenario, params)
        )
    return {
        "placement": placement,
        "wire": "near_straight" if straight else "curved",
        "cameras": n_cameras,
        "trials": trials,
        "success_rate": float(np.mean(rows["ok"])),
        "random_init_success_rate": float(np.mean(rows["rand_ok"])),
        "random_init_convergence_rate": float(np.mean(rows["rand_converged"])),
        "random_init_confident_outside_band_rate": float(np.mean(rows["rand_bad"])),
        "confident_rate": float(np.mean(rows["conf"])),
        "confident_outside_band_rate": float(np.mean(rows["bad"])),
        "median_fit_ms": _median(rows["fit_ms"]),
        "median_fit_thread_cpu_ms": _median(rows["fit_cpu_ms"]),
        "median_distance_transform_ms_per_keyframe": _median(rows["dt_ms"]),
        "curve_error_m_median": _median(rows["curve"]),
        "vertex_error_m_median": _median(rows["vertex"]),
        "sag_error_m_median": _median(rows["sag"]),
    }


def _long_wire_cell(
    rng: Any, camera: Any, params: Any, placement: str, trials: int, near_m: float, far_m: float
) -> dict[str, Any]:
    """Wires 80 m long seen by 16 views: only part of the fitted span is ever in view (3.7.1)."""
    import numpy as np

    from mapping.catenary.fit import reconstruct_catenary
    from mapping.catenary.sim import observed_curve_error_m, random_scenario

    errors, confident = [], []
    for _ in range(trials):
        scenario = random_scenario(
            rng, camera, 16, placement, False, params.half_span_m, wire_half_span_m=LONG_WIRE_M
        )
        fit = reconstruct_catenary(scenario.views(camera), params, near_m, far_m)
        errors.append(observed_curve_error_m(fit, scenario.theta_true, LONG_WIRE_M))
        confident.append(fit.confident)
    return {
        "placement": placement,
        "wire_half_span_m": LONG_WIRE_M,
        "trials": trials,
        "success_rate": float(np.mean(np.array(errors) <= SUCCESS_TOLERANCE_M)),
        "confident_rate": float(np.mean(confident)),
        "observed_curve_error_m_median": _median(errors),
    }


def _noisy_cell(
    rng: Any, camera: Any, params: Any, trials: int, near_m: float, far_m: float
) -> dict[str, Any]:
    """16 avoidance keyframes with CNN-like masks (thick, gaps, blobs) through instances."""
    import numpy as np

    from mapping.catenary.instances import reconstruct_wires
    from mapping.catenary.sim import cnn_like_mask, curve_error_m, random_scenario

    ok, confident, outside = [], [], []
    for trial in range(trials):
        scenario = random_scenario(
            rng, camera, 16, "avoidance", bool(trial % 2), params.half_span_m
        )
        masks = [cnn_like_mask(rng, m) for m in scenario.masks]
        fits = reconstruct_wires(
            camera, scenario.poses, masks, scenario.stamps_s, params, near_m, far_m
        )
        errors = [curve_error_m(f.theta, scenario.theta_true, params.half_span_m) for f in fits]
        if not fits:
            ok.append(False)
            confident.append(False)
            outside.append(False)
            continue
        best = fits[int(np.argmin(errors))]
        ok.append(min(errors) <= SUCCESS_TOLERANCE_M)
        confident.append(best.confident)
        outside.append(best.confident and not _inside_tube_band(best, scenario, params))
    return {
        "trials": trials,
        "success_rate": float(np.mean(ok)),
        "confident_rate": float(np.mean(confident)),
        "confident_outside_band_rate": float(np.mean(outside)),
    }


def _degenerate_case(camera: Any, params: Any, depth_near_m: float, depth_far_m: float) -> dict:
    """Fig. 3.10: the two-camera avoidance degeneracy, fitted and assessed."""
    import numpy as np

    from mapping.catenary.fit import reconstruct_catenary
    from mapping.catenary.sim import curve_error_m, degenerate_two_camera_scenario

    scenario = degenerate_two_camera_scenario(camera, params.half_span_m)
    fit = reconstruct_catenary(scenario.views(camera), params, depth_near_m, depth_far_m)
    observed = fit.uncertainty.observed
    return {
        "rms_residual_px": fit.rms_residual_px,
        "curve_error_m": curve_error_m(fit.theta, scenario.theta_true, params.half_span_m),
        "ill_conditioned": fit.ill_conditioned,
        "confident": fit.confident,
        "condition_number": fit.uncertainty.condition_number,
        "max_point_sigma_m": float(np.max(fit.uncertainty.point_sigma_m[observed]))
        if observed.any()
        else None,
    }


def bench_catenary_report(trials: int, seed: int, settings_path: Path | None) -> dict[str, Any]:
    """The 3.4.1 simulation experiments as one JSON-able report."""
    import numpy as np

    from companion.cli.settings import load_sim_settings
    from mapping.catenary.sim import sim_camera

    settings = load_sim_settings(settings_path)
    params = settings.catenary
    near_m = settings.mapping.wire_depth_near_m
    far_m = settings.mapping.wire_depth_far_m
    camera = sim_camera()
    rng = np.random.default_rng(seed)
    cells = [
        _scenario_cell(rng, camera, params, placement, straight, n, trials, near_m, far_m)
        for placement in ("avoidance", "random")
        for straight in (False, True)
        for n in (2, 4, 16)
    ]
    sixteen = [c for c in cells if c["cameras"] == 16]
    avoidance = [c for c in cells if c["placement"] == "avoidance"]
    return {
        "success_rate": float(np.mean([c["success_rate"] for c in cells])),
        "median_fit_ms": float(np.median([c["median_fit_ms"] for c in sixteen])),
        "median_fit_thread_cpu_ms": float(
            np.median([c["median_fit_thread_cpu_ms"] for c in sixteen])
        ),
        "vertex_error_m_median": float(np.median([c["vertex_error_m_median"] for c in cells])),
        "avoidance_success_rate": float(np.mean([c["success_rate"] for c in avoidance])),
        "avoidance_random_init_success_rate": float(
            np.mean([c["random_init_success_rate"] for c in avoidance])
        ),
        "avoidance_random_init_convergence_rate": float(
            np.mean([c["random_init_convergence_rate"] for c in avoidance])
        ),
        "confident_outside_band_rate": float(
            np.mean([c["confident_outside_band_rate"] for c in cells])
        ),
        "success_tolerance_m": SUCCESS_TOLERANCE_M,
        "parameterisation": params.parameterisation,
        "points_per_curve": params.points_per_curve,
        "degenerate_two_camera_case": _degenerate_case(camera, params, near_m, far_m),
        "cnn_like_masks_avoidance_16": _noisy_cell(rng, camera, params, trials, near_m, far_m),
        "long_wires": [
            _long_wire_cell(rng, camera, params, placement, trials, near_m, far_m)
            for placement in ("avoidance", "random")
        ],
        "scenarios": cells,
        "note": (
            "median_fit_ms: wall clock (includes the data-driven seeding) for 16 keyframes; "
            "on a shared machine also see median_fit_thread_cpu_ms; "
            "success = symmetric mean curve distance <= success_tolerance_m; random init: "
            "Theta drawn inside view 0's frustum (vertex pixel anywhere, depth in the wire prior, "
            "any yaw, a in 10-3000 m); converged = success, or a cost f within 5% of the "
            "data-seeded fit's or below it (the same minimum; with 2 avoidance views even that "
            "minimum can be wrong, Fig. 3.10, and such fits are never confident)"
        ),
    }


def register(app: typer.Typer, bench: typer.Typer) -> None:
    """Add this domain's commands to the root app and its benchmarks to `wireavoid bench`."""

    @bench.command("catenary")
    def bench_catenary(
        trials: Annotated[int, typer.Option(min=1, help="trials per scenario cell")] = 20,
        seed: Annotated[int, typer.Option(help="random seed of the simulation")] = 0,
        config: Annotated[
            Path | None,
            typer.Option("--config", help="TOML settings file", exists=True, dir_okay=False),
        ] = None,
        as_json: Annotated[bool, typer.Option("--json", help="print the report as JSON")] = False,
    ) -> None:
        """Multi-view catenary reconstruction on the simulated scenarios of thesis 3.4.1."""
        report = bench_catenary_report(trials, seed, config)
        if as_json:
            typer.echo(json.dumps(report, indent=2))
            return
        for cell in report["scenarios"]:
            typer.echo(
                f"{cell['placement']:9s} {cell['wire']:13s} {cell['cameras']:2d} cams: "
                f"success {cell['success_rate']:.2f} (random init "
                f"{cell['random_init_success_rate']:.2f}), fit {cell['median_fit_ms']:.1f} ms, "
                f"vertex {cell['vertex_error_m_median']:.3f} m"
            )
        summary = {k: v for k, v in report.items() if k != "scenarios"}
        typer.echo(json.dumps(summary, indent=2))
