//! `grin bench accuracy`: every method of [`crate::methods`] on every case of
//! [`crate::cases`], error against cost; the Pareto front; measured convergence orders.
//!
//! Error of a run = the worst ray's error (exit direction in radians, exit position and
//! optical path relative to the case's length scale). A ray that does not end `exited`
//! where the reference does makes the whole run *failed* (infinite error): a method that
//! loses rays is not a point on the chart. Cost = field evaluations per ray (exact, the
//! tracer counts them) and ns per ray (wall time on one thread; runs go in parallel, so it
//! is only comparable within one run).

use std::time::Instant;

use glam::DVec3;
use grin_scene::{ExitMethod, IntegratorKind};
use grin_trace::{RayResult, RayStatus, TraceSettings, trace_ray};
use rayon::prelude::*;

use crate::cases::{Case, Exit};
use crate::methods::{Method, Policy, Precision, all_methods};

/// Tolerance of the numerical reference, relative to the case's length scale.
pub const REFERENCE_TOL: f64 = 1e-12;

/// The reference exits of a case and how far the numerical reference is from the exact
/// solution (where there is one).
#[derive(Debug, Clone)]
pub struct Reference {
    pub exits: Vec<Exit>,
    /// Worst exit-direction difference (rad) numerical reference vs exact; `None` without
    /// an exact solution.
    pub numeric_vs_exact: Option<f64>,
}

/// Trace a ray in the chosen precision.
pub fn trace(
    field: &dyn grin_field::IndexField,
    settings: &TraceSettings,
    precision: Precision,
    origin: DVec3,
    dir: DVec3,
) -> RayResult {
    match precision {
        Precision::F64 => trace_ray::<f64>(field, settings, origin, dir),
        Precision::F32 => trace_ray::<f32>(field, settings, origin, dir),
    }
}

/// `auto` resolved on `pilots` in the chosen precision, every integrator a candidate
/// (as for a scene that names none).
pub fn choose_auto(
    field: &dyn grin_field::IndexField,
    settings: &TraceSettings,
    precision: Precision,
    pilots: &[(DVec3, DVec3)],
) -> Option<grin_trace::auto::AutoChoice> {
    match precision {
        Precision::F64 => grin_trace::auto::choose::<f64>(field, settings, true, pilots),
        Precision::F32 => grin_trace::auto::choose::<f32>(field, settings, true, pilots),
    }
}

/// Settings of the numerical reference.
pub fn reference_settings(scale: f64) -> TraceSettings {
    Method {
        integrator: IntegratorKind::Adaptive,
        policy: Policy::Adaptive,
        exit: ExitMethod::Bisection,
        precision: Precision::F64,
    }
    .settings(REFERENCE_TOL, scale)
}

/// Compute the reference of `case`: exact where known (the numerical one fills in the
/// optical path where the exact solution has none), else numerical on the source field.
pub fn reference(case: &Case) -> anyhow::Result<Reference> {
    let settings = reference_settings(case.scale);
    let numeric: Vec<RayResult> = case
        .rays
        .par_iter()
        .map(|&(o, d)| trace_ray::<f64>(case.source.as_ref(), &settings, o, d))
        .collect();
    if let Some((i, r)) = numeric
        .iter()
        .enumerate()
        .find(|(_, r)| r.status != RayStatus::Exited)
    {
        anyhow::bail!(
            "case {}: the reference ray {i} ended `{}`, not `exited` (the case is broken)",
            case.name,
            r.status.name()
        );
    }
    match &case.exact {
        None => Ok(Reference {
            exits: numeric
                .iter()
                .map(|r| Exit {
                    position: r.position,
                    direction: r.direction,
                    opl: Some(r.opl),
                })
                .collect(),
            numeric_vs_exact: None,
        }),
        Some(exact) => {
            let worst = exact
                .iter()
                .zip(&numeric)
                .map(|(e, r)| angle(e.direction, r.direction))
                .fold(0.0, f64::max);
            let exits = exact
                .iter()
                .zip(&numeric)
                .map(|(e, r)| Exit {
                    opl: e.opl.or(Some(r.opl)),
                    ..*e
                })
                .collect();
            Ok(Reference {
                exits,
                numeric_vs_exact: Some(worst),
            })
        }
    }
}

pub use grin_trace::auto::angle;

/// One run: a method at one parameter on one case.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Point {
    pub case: String,
    pub integrator: &'static str,
    pub policy: &'static str,
    pub exit: &'static str,
    pub precision: &'static str,
    /// Step (fixed; the heuristic's max) or tolerance, relative to the case's scale.
    pub param: f64,
    /// Worst exit-direction error, rad (infinite when failed).
    pub err_dir: f64,
    /// Worst exit-position error / scale.
    pub err_pos: f64,
    /// Worst optical-path error / scale.
    pub err_opl: f64,
    pub evals_per_ray: f64,
    pub steps_per_ray: f64,
    pub ns_per_ray: f64,
    /// Rays that did not end `exited` (any makes the run failed).
    pub failed_rays: usize,
    /// Rays that left `degraded` (their own error estimate above the limit; their error
    /// is measured like the others').
    pub degraded_rays: usize,
    pub rays: usize,
    /// `auto`: what the pilot rays chose ("" for the other policies).
    pub chosen: String,
    /// `auto`: field evaluations the pilot rays cost, in all (not in evals_per_ray: in a
    /// render they are spread over every pixel).
    pub pilot_evals: u64,
    #[serde(skip)]
    pub method: Method,
}

impl Point {
    pub fn failed(&self) -> bool {
        self.failed_rays > 0 || !self.err_dir.is_finite()
    }
}

/// Run `method` at `param` on `case` against `reference`.
pub fn run_point(case: &Case, reference: &Reference, method: Method, param: f64) -> Point {
    let mut settings = method.settings(param, case.scale);
    let mut chosen = String::new();
    let mut pilot_evals = 0;
    if method.policy == Policy::Auto {
        let choice = choose_auto(
            case.field.as_ref(),
            &settings,
            method.precision,
            &case.pilots,
        );
        if let Some(c) = choice {
            settings = c.settings;
            chosen = c.describe();
            pilot_evals = c.spent_evals;
        }
    }
    let start = Instant::now();
    let results: Vec<RayResult> = case
        .rays
        .iter()
        .map(|&(o, d)| trace(case.field.as_ref(), &settings, method.precision, o, d))
        .collect();
    let ns = start.elapsed().as_nanos() as f64;
    let mut p = Point {
        case: case.name.clone(),
        integrator: method.integrator_label(),
        policy: method.policy.name(),
        exit: crate::methods::exit_name(method.exit),
        precision: method.precision.name(),
        param,
        err_dir: 0.0,
        err_pos: 0.0,
        err_opl: 0.0,
        evals_per_ray: 0.0,
        steps_per_ray: 0.0,
        ns_per_ray: ns / results.len() as f64,
        failed_rays: 0,
        degraded_rays: 0,
        rays: results.len(),
        chosen,
        pilot_evals,
        method,
    };
    for (r, e) in results.iter().zip(&reference.exits) {
        p.evals_per_ray += r.evals as f64;
        p.steps_per_ray += f64::from(r.steps);
        if r.status == RayStatus::Degraded {
            p.degraded_rays += 1;
        }
        if !r.status.left() {
            p.failed_rays += 1;
            continue;
        }
        // NaN compares false with max: count it as infinite.
        let inf_nan = |x: f64| if x.is_nan() { f64::INFINITY } else { x };
        p.err_dir = p.err_dir.max(inf_nan(angle(r.direction, e.direction)));
        p.err_pos = p
            .err_pos
            .max(inf_nan((r.position - e.position).length() / case.scale));
        if let Some(opl) = e.opl {
            p.err_opl = p.err_opl.max(inf_nan((r.opl - opl).abs() / case.scale));
        }
    }
    p.evals_per_ray /= results.len() as f64;
    p.steps_per_ray /= results.len() as f64;
    if p.failed_rays > 0 {
        p.err_dir = f64::INFINITY;
        p.err_pos = f64::INFINITY;
        p.err_opl = f64::INFINITY;
    }
    p
}

/// A measured convergence order: slope of log(err_dir) against log(step).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Order {
    pub case: String,
    pub integrator: &'static str,
    pub exit: &'static str,
    pub precision: &'static str,
    /// The integrator's formal order.
    pub formal: u32,
    /// Least-squares slope over the points used (None: fewer than 3 in range).
    pub measured: Option<f64>,
    pub points_used: usize,
}

/// Errors below this (rad) are at the reference's or the precision's floor and above
/// `ORDER_MAX_ERR` outside the asymptotic range: neither is used in order fits.
pub const ORDER_MIN_ERR_F64: f64 = 1e-10;
pub const ORDER_MIN_ERR_F32: f64 = 1e-5;
pub const ORDER_MAX_ERR: f64 = 1e-2;

/// Convergence orders of every integrator with fixed steps, on each smooth case.
pub fn orders(cases: &[Case], points: &[Point]) -> Vec<Order> {
    let mut out = Vec::new();
    for case in cases.iter().filter(|c| c.smooth) {
        for &integrator in &IntegratorKind::ALL {
            for exit in [ExitMethod::Hermite, ExitMethod::Bisection] {
                for precision in [Precision::F64, Precision::F32] {
                    let floor = match precision {
                        Precision::F64 => ORDER_MIN_ERR_F64,
                        Precision::F32 => ORDER_MIN_ERR_F32,
                    };
                    let pts: Vec<&Point> = points
                        .iter()
                        .filter(|p| {
                            p.case == case.name
                                && p.method.integrator == integrator
                                && p.method.policy == Policy::Fixed
                                && p.method.exit == exit
                                && p.method.precision == precision
                        })
                        .collect();
                    if pts.is_empty() {
                        continue;
                    }
                    let used: Vec<&&Point> = pts
                        .iter()
                        .filter(|p| !p.failed() && p.err_dir > floor && p.err_dir < ORDER_MAX_ERR)
                        .collect();
                    let measured = (used.len() >= 3).then(|| {
                        let hs: Vec<f64> = used.iter().map(|p| p.param).collect();
                        let es: Vec<f64> = used.iter().map(|p| p.err_dir).collect();
                        log_slope(&hs, &es)
                    });
                    out.push(Order {
                        case: case.name.clone(),
                        integrator: crate::methods::integrator_label(integrator),
                        exit: crate::methods::exit_name(exit),
                        precision: precision.name(),
                        formal: grin_trace::integrate::order(integrator),
                        measured,
                        points_used: used.len(),
                    });
                }
            }
        }
    }
    out
}

/// Least-squares slope of log(y) against log(x).
pub fn log_slope(xs: &[f64], ys: &[f64]) -> f64 {
    let n = xs.len() as f64;
    let lx: Vec<f64> = xs.iter().map(|x| x.ln()).collect();
    let ly: Vec<f64> = ys.iter().map(|y| y.ln()).collect();
    let mx = lx.iter().sum::<f64>() / n;
    let my = ly.iter().sum::<f64>() / n;
    let sxy: f64 = lx.iter().zip(&ly).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = lx.iter().map(|x| (x - mx) * (x - mx)).sum();
    sxy / sxx
}

/// Indices of the Pareto front of `points` (err_dir against evals_per_ray): no other
/// point is both cheaper and more accurate. Sorted by cost.
pub fn pareto(points: &[&Point]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..points.len()).filter(|&i| !points[i].failed()).collect();
    idx.sort_by(|&a, &b| {
        points[a]
            .evals_per_ray
            .total_cmp(&points[b].evals_per_ray)
            .then(points[a].err_dir.total_cmp(&points[b].err_dir))
    });
    let mut front = Vec::new();
    let mut best = f64::INFINITY;
    for i in idx {
        if points[i].err_dir < best {
            best = points[i].err_dir;
            front.push(i);
        }
    }
    front
}

/// The cheapest point with err_dir <= target (the method to use at that error).
pub fn cheapest_at<'a>(points: &[&'a Point], target: f64) -> Option<&'a Point> {
    points
        .iter()
        .filter(|p| !p.failed() && p.err_dir <= target)
        .min_by(|a, b| a.evals_per_ray.total_cmp(&b.evals_per_ray))
        .copied()
}

/// Error decades the summary names a method for.
pub const DECADES: [f64; 3] = [1e-2, 1e-4, 1e-6];

/// Everything one accuracy run measured.
#[derive(Debug, Clone)]
pub struct AccuracyRun {
    pub cases: Vec<Case>,
    pub references: Vec<Reference>,
    pub points: Vec<Point>,
    pub orders: Vec<Order>,
    pub seconds: f64,
}

/// Run the sweep over `cases`; `progress(done, total)` after each case's method.
pub fn run(
    cases: Vec<Case>,
    quick: bool,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> anyhow::Result<AccuracyRun> {
    let start = Instant::now();
    let methods = all_methods(quick);
    let jobs: Vec<(usize, Method, f64)> = (0..cases.len())
        .flat_map(|c| {
            methods
                .iter()
                .flat_map(move |m| m.params(quick).into_iter().map(move |p| (c, *m, p)))
        })
        .collect();
    let references: Vec<Reference> = cases.iter().map(reference).collect::<Result<_, _>>()?;
    let total = jobs.len() as u64;
    let done = std::sync::atomic::AtomicU64::new(0);
    let points: Vec<Point> = jobs
        .par_iter()
        .map(|&(c, m, p)| {
            let pt = run_point(&cases[c], &references[c], m, p);
            let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(d, total);
            pt
        })
        .collect();
    let orders = orders(&cases, &points);
    Ok(AccuracyRun {
        cases,
        references,
        points,
        orders,
        seconds: start.elapsed().as_secs_f64(),
    })
}
