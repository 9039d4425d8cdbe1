"""Non-linear least-squares fit of one catenary to N keyframes (thesis 3.3.3, eq. 3.9, 3.38).

scipy's trust-region-reflective solver (`least_squares(method="trf")`) with the analytic
Jacobian of `mapping.catenary.jacobian`, solving either for Theta (eq. 3.2) or for the
inverse-depth Psi (eq. 3.33): first on the thesis' cost r^T r / 2 (eq. 3.13), then a short
refinement with a robust loss (`CatenaryParams.robust_loss`). Every fit comes back with its
covariance (eq. 3.39-3.40), its observed extent (3.7.1) and a `confident` verdict; an
ill-conditioned fit (Fig. 3.10) is reported as such, never as an answer to use.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from mapping.catenary.init import hop_hypotheses, ranked_hypotheses, seed_hypotheses
from mapping.catenary.jacobian import Projection, project_catenary
from mapping.catenary.kernel import residuals_and_jacobian
from mapping.catenary.model import sample_abscissae_m
from mapping.catenary.params import CatenaryParams
from mapping.catenary.residuals import CatenaryViews
from mapping.catenary.uncertainty import (
    FitUncertainty,
    fit_uncertainty,
    inverse_depth_from_theta,
    theta_from_inverse_depth,
    theta_jacobian_wrt_inverse_depth,
)


@dataclass(frozen=True, slots=True)
class CatenaryFit:
    """A fitted catenary with its quality; `confident` says whether to use it.

    theta: `(5,)` (x_v, y_v, z_v m NED, psi rad, a m) (eq. 3.2).
    stamp_s: sample time of the newest keyframe used, s.
    converged: the r^T r solve stopped on a tolerance (not on max_nfev or an error); the
        robust refinement is a bounded polish and may use up its evaluations.
    cost: f = r^T r / 2 (eq. 3.13) at the solution, residuals normalised by the diagonal.
    rms_residual_px: RMS of the residuals in pixels.
    n_evaluations: residual evaluations used.
    x_cat_m: `(M,)` sample abscissae; points_ned_m `(M, 3)` the samples, NED, m.
    uncertainty: `FitUncertainty` (covariance, condition number, per-point sigma, observed).
    extent_x_cat_m: `(2,)` [min, max] abscissae of observed samples (3.7.1); NaN if none.
    ill_conditioned: the data do not pin the curve down (Fig. 3.10): singular covariance,
        condition number above `max_condition_number`, or an observed sample's sigma above
        `max_point_sigma_m`. Such a fit is reported, never used.
    confident: converged, enough views, not ill-conditioned, small residual and enough
        observed samples.
    """

    theta: np.ndarray
    stamp_s: float
    converged: bool
    cost: float
    rms_residual_px: float
    n_evaluations: int
    x_cat_m: np.ndarray
    points_ned_m: np.ndarray
    uncertainty: FitUncertainty
    extent_x_cat_m: np.ndarray
    ill_conditioned: bool
    confident: bool

    @property
    def observed_points_ned_m(self) -> np.ndarray:
        """`(K, 3)` the samples within the observed extent, NED, m."""
        return self.points_ned_m[self.observed_span]

    @property
    def observed_span(self) -> np.ndarray:
        """`(M,) bool`, samples whose abscissa lies within the observed extent."""
        lo, hi = self.extent_x_cat_m
        return (self.x_cat_m >= lo) & (self.x_cat_m <= hi)


class _Problem:
    """Residuals and Jacobian in the solved parameters x, from one compiled chain evaluation
    (`catenary_kernel.residuals_and_jacobian`) shared by the two calls at the same x."""

    def __init__(
        self,
        views: CatenaryViews,
        x_cat_m: np.ndarray,
        params: CatenaryParams,
        to_theta: Callable[[np.ndarray], np.ndarray],
        theta_jac: Callable[[np.ndarray], np.ndarray],
    ) -> None:
        self.views = views
        self.exit_gate_px = params.extrapolation_gate_px
        self.x_cat_m = x_cat_m
        self.min_depth_m = params.min_depth_m
        self.to_theta = to_theta
        self.theta_jac = theta_jac
        self._x = np.full(5, np.nan)
        self._evaluation: tuple[np.ndarray, np.ndarray] | None = None

    def _evaluate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(r, dr/dTheta) at x, cached for the other of the two calls."""
        if self._evaluation is None or not np.array_equal(x, self._x):
            self._x = np.array(x, dtype=float)
            self._evaluation = residuals_and_jacobian(
                self.to_theta(self._x),
                self.x_cat_m,
                self.views,
                self.min_depth_m,
                self.exit_gate_px,
            )
        return self._evaluation

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """`(N M,)` r (eq. 3.4)."""
        return self._evaluate(x)[0]

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """`(N M, 5)` dr/dx = dr/dTheta (eq. 3.14) dTheta/dx."""
        return self._evaluate(x)[1] @ self.theta_jac(x)


def _solved_space(
    views: CatenaryViews, params: CatenaryParams
) -> tuple[
    Callable[[np.ndarray], np.ndarray],
    Callable[[np.ndarray], np.ndarray],
    Callable[[np.ndarray], np.ndarray],
    tuple[np.ndarray, np.ndarray],
]:
    """(x -> Theta, x -> dTheta/dx, Theta -> x, bounds) of the configured parameterisation."""
    inf = np.inf
    if params.parameterisation == "inverse_depth":
        lower = np.array([-inf, -inf, 1.0 / params.max_depth_m, -inf, params.sag_min_m])
        upper = np.array([inf, inf, 1.0 / params.min_depth_m, inf, params.sag_max_m])
        return (
            lambda x: theta_from_inverse_depth(x, views),
            lambda x: theta_jacobian_wrt_inverse_depth(x, views),
            lambda theta: inverse_depth_from_theta(theta, views),
            (lower, upper),
        )
    lower = np.array([-inf, -inf, -inf, -inf, params.sag_min_m])
    upper = np.array([inf, inf, inf, inf, params.sag_max_m])
    return (lambda x: np.asarray(x, float), lambda x: np.eye(5), lambda t: t, (lower, upper))


def fit_catenary(views: CatenaryViews, theta0: np.ndarray, params: CatenaryParams) -> CatenaryFit:
    """Theta* = argmin f (eq. 3.9) from the initial Theta `theta0`, with its uncertainty.

    A local solve (`local_fit`), then, while the best fit is neither confident nor explains
    the data (RMS above `hop_stop_rms_px`), up to `hop_rounds` rounds of basin hopping: the
    cheapest re-anchored hypothesis and the `hop_starts` cheapest perturbed ones of
    `hop_hypotheses` around the best fit are solved, and the best fit is kept (confident
    first, then lowest cost f). A bad initialisation inside the view frusta then reaches the
    wire about as often as the data-driven seeds do (`wireavoid bench catenary`).
    """
    best = local_fit(views, theta0, params)
    for _ in range(params.hop_rounds):
        if best.confident or best.rms_residual_px <= params.hop_stop_rms_px:
            break
        around, anchored = hop_hypotheses(views, params, best.theta)
        hypotheses = [
            *ranked_hypotheses(views, params, anchored)[:1],
            *ranked_hypotheses(views, params, around)[: params.hop_starts],
        ]
        fits = [local_fit(views, h, params) for h in hypotheses]
        better = [f for f in fits if _preferred(f, best)]
        if not better:
            break
        for fit in better:
            best = fit if _preferred(fit, best) else best
    return best


def _preferred(fit: CatenaryFit, other: CatenaryFit) -> bool:
    """True if `fit` beats `other`: confident over not, then by lower cost f (eq. 3.13)."""
    return (fit.confident, -fit.cost) > (other.confident, -other.cost)


def local_fit(views: CatenaryViews, theta0: np.ndarray, params: CatenaryParams) -> CatenaryFit:
    """One local solve of eq. 3.9 from `theta0`: r^T r, then the robust refinement.

    With the inverse-depth parameterisation the vertex of `theta0` must lie in front of
    view 0 (the reference keyframe C_1 of eq. 3.33).
    """
    x_cat_m = sample_abscissae_m(params.half_span_m, params.points_per_curve)
    to_theta, theta_jac, from_theta, (lower, upper) = _solved_space(views, params)
    problem = _Problem(views, x_cat_m, params, to_theta, theta_jac)
    x0 = np.clip(from_theta(np.asarray(theta0, dtype=float)), lower, upper)
    solve = partial(
        least_squares,
        problem.residuals,
        jac=problem.jacobian,
        bounds=(lower, upper),
        method="trf",
        f_scale=params.robust_scale_px / views.diagonal_px,
        x_scale="jac",
        ftol=params.tolerance,
        xtol=params.tolerance,
        gtol=params.tolerance,
    )
    # Converge with the thesis' quadratic cost (eq. 3.13), whose pull reaches far, then
    # refine with the robust loss, which lets go of samples no detection explains.
    solution = solve(x0, loss="linear", max_nfev=params.max_function_evaluations)
    converged = bool(solution.status > 0)
    if params.robust_loss != "linear":
        evaluations = solution.nfev
        solution = solve(
            solution.x, loss=params.robust_loss, max_nfev=params.robust_refinement_evaluations
        )
        solution.nfev += evaluations
    theta = to_theta(solution.x)
    projection = project_catenary(
        theta, x_cat_m, views, params.min_depth_m, params.extrapolation_gate_px
    )
    uncertainty = fit_uncertainty(
        theta,
        x_cat_m,
        views,
        projection,
        theta_jac(solution.x),
        params.min_depth_m,
        params.pixel_sigma_px,
        params.observation_gate_px,
        slip_sigma_m=params.half_span_m,
        samples_per_view=params.independent_samples_per_view,
    )
    return _assessed_fit(
        views, params, theta, x_cat_m, projection, solution, converged, uncertainty
    )


def _assessed_fit(
    views: CatenaryViews,
    params: CatenaryParams,
    theta: np.ndarray,
    x_cat_m: np.ndarray,
    projection: Projection,
    solution: OptimizeResult,
    converged: bool,
    uncertainty: FitUncertainty,
) -> CatenaryFit:
    """Package a solver result with its extent and the `confident` verdict."""
    observed = uncertainty.observed
    extent = (
        np.array([x_cat_m[observed].min(), x_cat_m[observed].max()])
        if observed.any()
        else np.full(2, np.nan)
    )
    rms_px = float(np.sqrt(np.mean(projection.residuals**2)) * views.diagonal_px)
    ill_conditioned = not (
        uncertainty.condition_number <= params.max_condition_number
        and bool(np.all(uncertainty.point_sigma_m[observed] <= params.max_point_sigma_m))
    )
    confident = (
        converged
        and views.n_views >= params.min_confident_views
        and not ill_conditioned
        and rms_px <= params.max_rms_residual_px
        and int(observed.sum()) >= params.min_observed_points
    )
    return CatenaryFit(
        theta=theta,
        stamp_s=float(views.stamps_s.max()),
        converged=converged,
        cost=float(solution.cost),
        rms_residual_px=rms_px,
        n_evaluations=int(solution.nfev),
        x_cat_m=x_cat_m,
        points_ned_m=projection.points_ned_m,
        uncertainty=uncertainty,
        extent_x_cat_m=extent,
        ill_conditioned=ill_conditioned,
        confident=confident,
    )


def reconstruct_catenary(
    views: CatenaryViews, params: CatenaryParams, depth_near_m: float, depth_far_m: float
) -> CatenaryFit:
    """Fit one wire seen by `views` from data-driven seeds (`mapping.catenary.init`).

    Seeds are tried in order of their cost, up to `max_starts`; the first confident fit is
    returned, else the fit of lowest cost (not confident, so reported but not used).
    depth_near_m / depth_far_m: the wire depth prior (`MappingParams.wire_depth_near_m` /
    `wire_depth_far_m`, 4.4.3) within which view 0's detections are back-projected.
    """
    seeds = ranked_hypotheses(
        views, params, seed_hypotheses(views, params, depth_near_m, depth_far_m)
    )
    best: CatenaryFit | None = None
    for seed in seeds[: params.max_starts]:
        fit = fit_catenary(views, seed, params)
        if fit.confident:
            return fit
        if best is None or fit.cost < best.cost:
            best = fit
    assert best is not None
    return best
