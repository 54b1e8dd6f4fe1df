//! `grin bench accuracy`: every method of [`crate::methods`] on every case of
//! [`crate::cases`], error against cost; the Pareto front; measured convergence orders.
//!
//! Error of a run = the worst ray's error (exit direction in radians, exit position and
//! optical path relative to the case's length scale). A ray that does not end `exited`
//! where the reference does makes the whole run *failed* (infinite error): a method that
//! loses rays is not a point on the chart. Cost = field evaluations per ray (exact, the
//! tracer counts them) and ns per ray (wall time on one thread; runs go in parallel, so it
//! is only comparable within one run).
//!
//! Over 600 lines: one concept, the sweep of every method over every case (its runs, errors, fronts
//! and orders).

use std::time::Instant;

use glam::DVec3;
use grin_render::settings::TraceSettings;
use grin_scene::{ExitMethod, IntegratorKind};
use grin_trace::{RayResult, RayStatus, trace_ray};
use rayon::prelude::*;

use crate::cases::{Case, Exit};
use crate::methods::{Method, Policy, Precision, all_methods};

/// Tolerance of the numerical reference, relative to the case's length scale.
pub const REFERENCE_TOL: f64 = 1e-14;

/// The reference exits of a case and how far the numerical reference is from the exact
/// solution (where there is one).
#[derive(Debug, Clone)]
pub struct Reference {
    pub exits: Vec<Exit>,
    /// Worst exit-direction difference (rad) numerical reference vs exact; `None` without
    /// an exact solution.
    pub numeric_vs_exact: Option<f64>,
}

/// Trace a ray on the CPU in the chosen precision ([`Precision::Gpu`]: the f32 twin).
pub fn trace(
    field: &dyn grin_field::IndexField,
    settings: &TraceSettings,
    precision: Precision,
    origin: DVec3,
    dir: DVec3,
) -> RayResult {
    match precision {
        Precision::F64 => trace_ray::<f64>(field, settings, origin, dir),
        Precision::F32 | Precision::Gpu => trace_ray::<f32>(field, settings, origin, dir),
    }
}

/// `auto` resolved on `pilots` in the chosen precision, every integrator a candidate
/// (as for a scene that names none). For the GPU, in the f32 twin on the CPU, as
/// `grin render --backend gpu` chooses.
pub fn choose_auto(
    field: &dyn grin_field::IndexField,
    settings: &TraceSettings,
    precision: Precision,
    pilots: &[(DVec3, DVec3)],
) -> Option<grin_trace::auto::AutoChoice> {
    match precision {
        Precision::F64 => grin_trace::auto::choose::<f64>(field, settings, true, pilots),
        Precision::F32 | Precision::Gpu => {
            grin_trace::auto::choose::<f32>(field, settings, true, pilots)
        }
    }
}

/// Settings of the numerical reference (its optical path under error control too).
pub fn reference_settings(scale: f64) -> TraceSettings {
    let method = Method {
        integrator: IntegratorKind::Adaptive,
        policy: Policy::Adaptive,
        exit: ExitMethod::Bisection,
        precision: Precision::F64,
    };
    TraceSettings {
        opl_control: true,
        ..method.settings(REFERENCE_TOL, scale)
    }
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
    /// Wall time a ray: on the CPU one thread's (runs go in parallel: compare within a
    /// run); on the GPU the kernel's time over `timed_rays` (copies of the case's rays in
    /// one dispatch), divided by them.
    pub ns_per_ray: f64,
    /// Rays the time was taken over.
    pub timed_rays: usize,
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

/// The tracer settings of `method` at `param` on `case`: `auto` resolved on the case's
/// pilots. With what the pilots chose and what they cost ("", 0 for the other policies).
fn resolve(case: &Case, method: Method, param: f64) -> (TraceSettings, String, u64) {
    let settings = method.settings(param, case.scale);
    if method.policy == Policy::Auto
        && let Some(c) = choose_auto(
            case.field.as_ref(),
            &settings,
            method.precision,
            &case.pilots,
        )
    {
        return (c.settings, c.describe(), c.spent_evals);
    }
    (settings, String::new(), 0)
}

/// Run `method` at `param` on `case` against `reference`, on the CPU.
pub fn run_point(case: &Case, reference: &Reference, method: Method, param: f64) -> Point {
    let (settings, chosen, pilot_evals) = resolve(case, method, param);
    let start = Instant::now();
    let results: Vec<RayResult> = case
        .rays
        .iter()
        .map(|&(o, d)| trace(case.field.as_ref(), &settings, method.precision, o, d))
        .collect();
    let ns = start.elapsed().as_nanos() as f64;
    Point {
        ns_per_ray: ns / results.len() as f64,
        timed_rays: results.len(),
        chosen,
        pilot_evals,
        ..score(case, reference, method, param, &results)
    }
}

/// Field evaluations a timed GPU dispatch aims at (copies of the case's rays), and the
/// most copies: enough work to fill the adapter, little enough for a sweep.
pub const GPU_TIMED_EVALS: f64 = 2e5;
pub const GPU_MAX_COPIES: usize = 512;

/// Run `method` (its precision [`Precision::Gpu`]) at `param` on `case`'s baked field on
/// the GPU: the case's rays once for the results, then copies of them in one dispatch
/// for the time (about [`GPU_TIMED_EVALS`] evaluations).
pub fn run_gpu_point(
    gpu: &mut grin_gpu::GpuRayTracer,
    case: &Case,
    reference: &Reference,
    method: Method,
    param: f64,
) -> anyhow::Result<Point> {
    let Some(grid) = &case.grid else {
        anyhow::bail!("case {}: the GPU traces baked fields only", case.name);
    };
    gpu.set_field(grid.clone())?;
    let (settings, chosen, pilot_evals) = resolve(case, method, param);
    let (out, seconds) = gpu.trace(&settings, &case.rays, 1)?;
    let results: Vec<RayResult> = out.iter().map(gpu_result).collect();
    let evals: f64 = out.iter().map(|r| f64::from(r.evals)).sum();
    let copies = ((GPU_TIMED_EVALS / evals.max(1.0)).ceil() as usize).clamp(1, GPU_MAX_COPIES);
    let (seconds, timed) = if copies > 1 {
        let (_, s) = gpu.trace(&settings, &case.rays, copies)?;
        (s, case.rays.len() * copies)
    } else {
        (seconds, case.rays.len())
    };
    Ok(Point {
        ns_per_ray: seconds * 1e9 / timed as f64,
        timed_rays: timed,
        chosen,
        pilot_evals,
        ..score(case, reference, method, param, &results)
    })
}

/// A GPU ray as the CPU tracer reports one (no error estimate comes back: its status
/// says `degraded`).
pub fn gpu_result(g: &grin_gpu::march::GpuRay) -> RayResult {
    RayResult {
        status: RayStatus::ALL
            .get(g.status as usize)
            .copied()
            .unwrap_or(RayStatus::Error),
        position: g.position,
        direction: g.direction,
        opl: g.opl,
        length: g.length,
        swept: glam::DVec3::ZERO,
        steps: g.steps,
        evals: u64::from(g.evals),
        transmittance: g.transmittance,
        error_estimate: 0.0,
        crossing_uncertainty: 0.0,
    }
}

/// The errors and costs of a run from its rays' results (no time, no pilots yet).
fn score(
    case: &Case,
    reference: &Reference,
    method: Method,
    param: f64,
    results: &[RayResult],
) -> Point {
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
        ns_per_ray: 0.0,
        timed_rays: 0,
        failed_rays: 0,
        degraded_rays: 0,
        rays: results.len(),
        chosen: String::new(),
        pilot_evals: 0,
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
    /// The order the method can show on this field: its formal order, or less where the
    /// field is not smooth enough for it ([`crate::cases::Case::order_limit`]).
    pub expected: u32,
    /// Least-squares slope over the points used (None: fewer than 3 in range).
    pub measured: Option<f64>,
    /// The same fit of the optical path's error, where the case's exact solution gives
    /// the path (Luneburg, rod): it sees the phase along a ray, which the exit direction
    /// need not (rk4 on the lens: direction 5, path 4; docs/accuracy.md).
    pub measured_opl: Option<f64>,
    pub points_used: usize,
    /// The steps a ray of the runs fitted (finest last), so a reader sees the range.
    pub steps: String,
    pub verdict: OrderVerdict,
}

/// How a measured order compares with the expected one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, strum::IntoStaticStr)]
#[serde(rename_all = "kebab-case")]
#[strum(serialize_all = "lowercase")]
pub enum OrderVerdict {
    /// Within [`ORDER_TOLERANCE`] of the expected order.
    #[strum(serialize = "as expected")]
    AsExpected,
    /// Faster: the leading error term cancels (superconvergence) or the fit is still
    /// above the asymptotic range when the error reaches the floor.
    Faster,
    /// Slower by more than the tolerance.
    Slower,
    /// Fewer than 3 runs between the floor and `ORDER_MAX_ERR`.
    #[strum(serialize = "too few points")]
    TooFewPoints,
}

impl OrderVerdict {
    pub fn name(self) -> &'static str {
        self.into()
    }

    fn of(measured: Option<f64>, expected: u32) -> Self {
        match measured {
            None => Self::TooFewPoints,
            Some(m) if (m - f64::from(expected)).abs() <= ORDER_TOLERANCE => Self::AsExpected,
            Some(m) if m > f64::from(expected) => Self::Faster,
            Some(_) => Self::Slower,
        }
    }
}

/// Errors below this (rad) are at the reference's or the precision's floor and above
/// `ORDER_MAX_ERR` outside the asymptotic range: neither is used in order fits. In f64
/// the references (exact, or Dormand-Prince at [`REFERENCE_TOL`]) and the exit search
/// (`boundary::EXIT_TOL_REL`, 1e-14 R) leave errors of 1e-15 .. 1e-14 R: two decades
/// below this floor, so they move no fitted slope by more than ~0.01.
pub const ORDER_MIN_ERR_F64: f64 = 1e-12;
pub const ORDER_MIN_ERR_F32: f64 = 1e-5;
pub const ORDER_MAX_ERR: f64 = 1e-2;
/// An order is fitted over the finest this many runs inside the error window (two
/// halvings of the step): the asymptotic range, where the leading error term dominates.
/// A fit over the whole window mixes in the coarse, pre-asymptotic runs.
pub const ORDER_FIT_POINTS: usize = 3;
/// How far a measured order may be from the expected one and count as it.
pub const ORDER_TOLERANCE: f64 = 0.3;
/// A run is in an order fit only where the steps taken grew with the step asked for:
/// against the next coarser run of the sweep, steps a ray rose by at least this fraction
/// of the factor the step shrank by (halving the step: 1.67x the steps or more). Steps
/// capped at the field's feature size (the plume's R/2 .. R/8 take 14, 14 and 17 steps a
/// ray) are a mix of two step sizes, not a point of the h sequence.
pub const STEPS_FOLLOW_MIN: f64 = 0.83;

/// Convergence orders of every integrator with fixed steps, on each smooth case.
pub fn orders(cases: &[Case], points: &[Point]) -> Vec<Order> {
    let mut out = Vec::new();
    for case in cases.iter().filter(|c| c.smooth) {
        for &integrator in &IntegratorKind::ALL {
            for exit in [ExitMethod::Hermite, ExitMethod::Bisection] {
                for precision in Precision::ALL {
                    let floor = if precision.is_f32() {
                        ORDER_MIN_ERR_F32
                    } else {
                        ORDER_MIN_ERR_F64
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
                    let formal = grin_trace::integrate::order(integrator);
                    let expected = case.order_limit.map_or(formal, |l| formal.min(l));
                    // (step asked, steps a ray, error; infinite when the run failed)
                    let runs = |error: fn(&Point) -> f64| -> Vec<(f64, f64, f64)> {
                        pts.iter()
                            .map(|p| {
                                let e = if p.failed() { f64::INFINITY } else { error(p) };
                                (p.param, p.steps_per_ray, e)
                            })
                            .collect()
                    };
                    let (measured, used) = fit_order(&uncapped_runs(&runs(|p| p.err_dir)), floor);
                    // The optical path's order, where the case's exact solution gives it
                    // (the numerical references' own path sums sit near 1e-11).
                    let exact_opl = case
                        .exact
                        .as_ref()
                        .is_some_and(|e| e.iter().all(|x| x.opl.is_some()));
                    let measured_opl = exact_opl
                        .then(|| fit_order(&uncapped_runs(&runs(|p| p.err_opl)), floor).0)
                        .flatten();
                    let steps = used
                        .iter()
                        .map(|p| format!("{:.0}", p.0))
                        .collect::<Vec<_>>()
                        .join(" ");
                    out.push(Order {
                        case: case.name.clone(),
                        integrator: crate::methods::integrator_label(integrator),
                        exit: crate::methods::exit_name(exit),
                        precision: precision.name(),
                        formal,
                        expected,
                        measured,
                        measured_opl,
                        points_used: used.len(),
                        steps,
                        verdict: OrderVerdict::of(measured, expected),
                    });
                }
            }
        }
    }
    out
}

/// The runs of `runs` (step or its parameter, steps a ray, error) whose step was the one
/// asked for: their steps a ray rose by at least [`STEPS_FOLLOW_MIN`] of the factor the
/// step shrank by since the next coarser run (the coarsest run: up to the next finer
/// one; a capped run takes more steps than its step asks, so the rise to the next run is
/// short). Returns (steps a ray, error) for [`fit_order`].
pub fn uncapped_runs(runs: &[(f64, f64, f64)]) -> Vec<(f64, f64)> {
    let follows = |coarse: &(f64, f64, f64), fine: &(f64, f64, f64)| {
        fine.1 / coarse.1 >= STEPS_FOLLOW_MIN * (coarse.0 / fine.0)
    };
    let nearest = |run: &(f64, f64, f64), coarser: bool| {
        runs.iter()
            .filter(|r| if coarser { r.0 > run.0 } else { r.0 < run.0 })
            .min_by(|a, b| (a.0 - run.0).abs().total_cmp(&(b.0 - run.0).abs()))
    };
    runs.iter()
        .filter(|run| match (nearest(run, true), nearest(run, false)) {
            (Some(coarse), _) => follows(coarse, run),
            (None, Some(fine)) => follows(run, fine),
            (None, None) => false,
        })
        .map(|&(_, steps, err)| (steps, err))
        .collect()
}

/// The order of one method's fixed-step runs, each given as (steps a ray, exit-direction
/// error; infinite when it failed): the slope over the finest [`ORDER_FIT_POINTS`] runs
/// with `floor < error < ORDER_MAX_ERR`, and those runs (coarsest first). The step is the
/// one taken, not the one asked for: every policy caps steps at the field's feature size,
/// so R/2 .. R/8 can be the same run on the plume. 1 / steps a ray is proportional to the
/// mean step (the rays' paths are the same in every run); runs that took the same steps
/// count once.
pub fn fit_order(runs: &[(f64, f64)], floor: f64) -> (Option<f64>, Vec<(f64, f64)>) {
    let mut used: Vec<(f64, f64)> = Vec::new();
    for &(steps, err) in runs
        .iter()
        .filter(|(_, e)| *e > floor && *e < ORDER_MAX_ERR)
    {
        if !used.iter().any(|q| q.0 == steps) {
            used.push((steps, err));
        }
    }
    used.sort_by(|a, b| a.0.total_cmp(&b.0));
    let finest = used.split_off(used.len().saturating_sub(ORDER_FIT_POINTS));
    let measured = (finest.len() >= 3).then(|| {
        let hs: Vec<f64> = finest.iter().map(|p| 1.0 / p.0).collect();
        let es: Vec<f64> = finest.iter().map(|p| p.1).collect();
        log_slope(&hs, &es)
    });
    (measured, finest)
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
    pub gpu: GpuColumn,
}

/// What became of the GPU column.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct GpuColumn {
    /// The adapter the GPU runs ran on (`None`: no GPU runs).
    pub adapter: Option<String>,
    /// Why there are no GPU runs (not asked for, no adapter, no baked case).
    pub skipped: Option<String>,
    /// Pipelines the GPU runs compiled, and the GPU part's wall time.
    pub pipelines: usize,
    pub seconds: f64,
}

/// Run the sweep over `cases` on the CPU, then (`gpu`) the GPU column on the cases
/// with a baked field; `progress(done, total)` after each run.
pub fn run(
    cases: Vec<Case>,
    quick: bool,
    gpu: bool,
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
    let gpu_jobs: Vec<(usize, Method, f64)> = if gpu {
        let methods = crate::methods::gpu_methods(quick);
        (0..cases.len())
            .filter(|&c| cases[c].grid.is_some())
            .flat_map(|c| {
                methods
                    .iter()
                    .flat_map(move |m| m.params(quick).into_iter().map(move |p| (c, *m, p)))
                    .collect::<Vec<_>>()
            })
            .collect()
    } else {
        Vec::new()
    };
    let references: Vec<Reference> = cases.iter().map(reference).collect::<Result<_, _>>()?;
    let total = (jobs.len() + gpu_jobs.len()) as u64;
    let done = std::sync::atomic::AtomicU64::new(0);
    let tick = || {
        let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        progress(d, total);
    };
    let mut points: Vec<Point> = jobs
        .par_iter()
        .map(|&(c, m, p)| {
            let pt = run_point(&cases[c], &references[c], m, p);
            tick();
            pt
        })
        .collect();
    let mut column = GpuColumn::default();
    if !gpu {
        column.skipped = Some("not asked for (--no-gpu)".into());
    } else if gpu_jobs.is_empty() {
        column.skipped = Some("no case of this run has a baked field".into());
    } else {
        match grin_gpu::GpuContext::new_headless() {
            Err(e) => column.skipped = Some(format!("no GPU adapter: {e}")),
            Ok(ctx) => {
                let gpu_start = Instant::now();
                column.adapter = Some(ctx.adapter_name());
                let first = cases[gpu_jobs[0].0].grid.clone();
                let Some(first) = first else {
                    anyhow::bail!("a GPU job without a baked field");
                };
                let mut tracer = grin_gpu::GpuRayTracer::new(&ctx, first)?;
                for &(c, m, p) in &gpu_jobs {
                    points.push(run_gpu_point(&mut tracer, &cases[c], &references[c], m, p)?);
                    tick();
                }
                column.pipelines = tracer.pipelines_compiled();
                column.seconds = gpu_start.elapsed().as_secs_f64();
            }
        }
    }
    let orders = orders(&cases, &points);
    Ok(AccuracyRun {
        cases,
        references,
        points,
        orders,
        seconds: start.elapsed().as_secs_f64(),
        gpu: column,
    })
}
