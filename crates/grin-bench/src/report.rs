//! What `grin bench accuracy` writes: accuracy.csv (every run), orders.csv, summary.md
//! (the method to use per error decade, the paper's method beside it, measured orders)
//! and one chart per case and precision (SVG and PNG), all committed together.
//!
//! Over 600 lines: one concept, the sweep's files, made from one set of runs and committed
//! together.

use std::fmt::Write as _;
use std::path::Path;

use grin_output::{Staged, commit, stage_writer};
use grin_scene::ExitMethod;

use crate::accuracy::{
    AccuracyRun, DECADES, ORDER_FIT_POINTS, ORDER_MAX_ERR, ORDER_MIN_ERR_F32, ORDER_MIN_ERR_F64,
    ORDER_TOLERANCE, OrderVerdict, Point, REFERENCE_TOL, STEPS_FOLLOW_MIN, cheapest_at, pareto,
};
use crate::chart::{Chart, Curve, LineKind, png, svg};
use crate::methods::{Policy, Precision};

/// Points of one case and precision.
fn select<'a>(run: &'a AccuracyRun, case: &str, precision: Precision) -> Vec<&'a Point> {
    run.points
        .iter()
        .filter(|p| p.case == case && p.method.precision == precision)
        .collect()
}

/// `rk4 adaptive 1e-6 (hermite)`: a run as the summary names it.
pub fn point_name(p: &Point) -> String {
    let param = match p.method.policy {
        Policy::Adaptive => format!("tol {:.0e}", p.param),
        Policy::PerLength | Policy::Auto => format!("{:.0e} rad", p.param),
        _ => format!("ds {}", fraction(p.param)),
    };
    if p.method.policy == Policy::Auto {
        // The integrator is the pilots' choice: `auto 1e-4 rad (hermite exit)`.
        return format!("{} {} ({} exit)", p.policy, param, p.exit);
    }
    format!("{} {} {} ({} exit)", p.integrator, p.policy, param, p.exit)
}

/// 0.0625 -> "R/16".
fn fraction(x: f64) -> String {
    let inv = 1.0 / x;
    if (inv - inv.round()).abs() < 1e-9 {
        format!("R/{}", inv.round())
    } else {
        format!("{x}R")
    }
}

/// The chart of one case and precision.
pub fn case_chart(run: &AccuracyRun, case: &str, precision: Precision) -> Chart {
    let pts = select(run, case, precision);
    let mut curves = Vec::new();
    let integrators = grin_scene::IntegratorKind::ALL;
    for (ci, &kind) in integrators.iter().enumerate() {
        for policy in Policy::ALL.into_iter().filter(|&p| p != Policy::Auto) {
            for exit in [ExitMethod::Hermite, ExitMethod::Bisection] {
                // Bisection exits are drawn for the paper's method only (the CSV has all).
                let paper =
                    kind == grin_scene::IntegratorKind::Sharma && policy == Policy::Heuristic;
                if exit == ExitMethod::Bisection && !paper {
                    continue;
                }
                let mut c: Vec<(f64, f64)> = pts
                    .iter()
                    .filter(|p| {
                        p.method.integrator == kind
                            && p.method.policy == policy
                            && p.method.exit == exit
                            && !p.failed()
                    })
                    .map(|p| (p.evals_per_ray, p.err_dir))
                    .collect();
                if c.is_empty() {
                    continue;
                }
                c.sort_by(|a, b| a.0.total_cmp(&b.0));
                let mut label = format!(
                    "{} {}",
                    crate::methods::integrator_label(kind),
                    policy.name()
                );
                if exit == ExitMethod::Bisection {
                    label.push_str(" bisection (paper)");
                }
                curves.push(Curve {
                    label,
                    color: ci,
                    style: match policy {
                        _ if exit == ExitMethod::Bisection => LineKind::LongDash,
                        Policy::Fixed => LineKind::Solid,
                        Policy::Heuristic => LineKind::Dotted,
                        Policy::Adaptive => LineKind::Dashed,
                        Policy::PerLength | Policy::Auto => LineKind::Thick,
                    },
                    points: c,
                });
            }
        }
    }
    let mut auto: Vec<(f64, f64)> = pts
        .iter()
        .filter(|p| p.method.policy == Policy::Auto && p.method.exit == ExitMethod::Hermite)
        .filter(|p| !p.failed())
        .map(|p| (p.evals_per_ray, p.err_dir))
        .collect();
    if !auto.is_empty() {
        auto.sort_by(|a, b| a.0.total_cmp(&b.0));
        curves.push(Curve {
            label: "auto (pilot rays choose)".into(),
            color: integrators.len(),
            style: LineKind::Thick,
            points: auto,
        });
    }
    // The colours in use, in palette order.
    let mut colors: Vec<(usize, String)> = Vec::new();
    for c in &curves {
        if !colors.iter().any(|(i, _)| *i == c.color) {
            let name = if c.color < integrators.len() {
                crate::methods::integrator_label(integrators[c.color]).to_owned()
            } else {
                "auto (pilot rays choose)".to_owned()
            };
            colors.push((c.color, name));
        }
    }
    colors.sort();
    let front_idx = pareto(&pts);
    let front = front_idx
        .iter()
        .map(|&i| (pts[i].evals_per_ray, pts[i].err_dir))
        .collect();
    // One note per point: a run that is the cheapest at several decades names them all
    // (`<= 1e-2, 1e-4 rad: ...`) instead of printing over itself.
    let mut notes: Vec<(f64, f64, String)> = Vec::new();
    for target in DECADES {
        let Some(p) = cheapest_at(&pts, target) else {
            continue;
        };
        match notes
            .iter_mut()
            .find(|n| n.0 == p.evals_per_ray && n.1 == p.err_dir)
        {
            Some(n) => n.2 = n.2.replacen(" rad:", &format!(", {target:.0e} rad:"), 1),
            None => notes.push((
                p.evals_per_ray,
                p.err_dir,
                format!("<= {target:.0e} rad: {}", point_name(p)),
            )),
        }
    }
    Chart {
        title: format!(
            "{case}: exit-direction error vs cost ({})",
            precision.name()
        ),
        x_label: "field evaluations per ray".into(),
        y_label: "worst exit-direction error (rad)".into(),
        curves,
        front,
        notes,
        colors,
        styles: vec![
            (LineKind::Solid, "fixed step".into()),
            (LineKind::Dotted, "the paper's gradient heuristic".into()),
            (
                LineKind::LongDash,
                "the paper's method (heuristic, bisection exit)".into(),
            ),
            (LineKind::Dashed, "error control per step".into()),
            (
                LineKind::Thick,
                "error control per length; auto (pilots choose)".into(),
            ),
        ],
    }
}

/// The method to use at each decade, and what the paper's method costs there.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DecadeRow {
    pub case: String,
    pub precision: &'static str,
    pub target: f64,
    pub best: Option<String>,
    pub best_evals: Option<f64>,
    pub best_err: Option<f64>,
    pub paper_evals: Option<f64>,
    /// paper_evals / best_evals.
    pub paper_ratio: Option<f64>,
}

pub fn decade_rows(run: &AccuracyRun) -> Vec<DecadeRow> {
    let mut rows = Vec::new();
    for case in &run.cases {
        for precision in Precision::ALL {
            let pts = select(run, &case.name, precision);
            if pts.is_empty() {
                continue;
            }
            let paper: Vec<&Point> = pts
                .iter()
                .copied()
                .filter(|p| p.method.is_paper())
                .collect();
            for target in DECADES {
                let best = cheapest_at(&pts, target);
                let paper_best = cheapest_at(&paper, target);
                rows.push(DecadeRow {
                    case: case.name.clone(),
                    precision: precision.name(),
                    target,
                    best: best.map(point_name),
                    best_evals: best.map(|p| p.evals_per_ray),
                    best_err: best.map(|p| p.err_dir),
                    paper_evals: paper_best.map(|p| p.evals_per_ray),
                    paper_ratio: match (paper_best, best) {
                        (Some(a), Some(b)) => Some(a.evals_per_ray / b.evals_per_ray),
                        _ => None,
                    },
                });
            }
        }
    }
    rows
}

/// What the accuracy knob delivered: one `step = { auto = asked }` run, beside the
/// cheapest fixed-step run and the paper's method that reach the same error.
#[derive(Debug, Clone, serde::Serialize)]
pub struct AutoRow {
    pub case: String,
    pub precision: &'static str,
    pub integrator: &'static str,
    /// `auto`: what the pilot rays chose.
    pub chosen: String,
    pub asked: f64,
    pub delivered: f64,
    /// delivered / asked (<= 1: the knob kept its word).
    pub ratio: f64,
    pub evals: f64,
    /// Cheapest fixed-step run (any integrator, exit) with err_dir <= asked.
    pub best_fixed_evals: Option<f64>,
    /// Cheapest run of the paper's method with err_dir <= asked.
    pub paper_evals: Option<f64>,
    /// Field evaluations the pilots spent choosing (reference and every candidate).
    pub pilot_evals: u64,
    /// `evals` with the pilots' spread over a 640x360 frame ([`FRAME_PIXELS`] rays).
    pub evals_with_pilots: f64,
    /// `evals_with_pilots` over `best_fixed_evals` (the cheapest in hindsight).
    pub over_best: Option<f64>,
    /// `paper_evals` over `evals_with_pilots`.
    pub paper_over: Option<f64>,
}

pub fn auto_rows(run: &AccuracyRun) -> Vec<AutoRow> {
    let mut rows = Vec::new();
    for p in run.points.iter().filter(|p| {
        matches!(p.method.policy, Policy::Auto | Policy::PerLength)
            && p.method.exit == ExitMethod::Hermite
    }) {
        let same: Vec<&Point> = select(run, &p.case, p.method.precision);
        let fixed: Vec<&Point> = same
            .iter()
            .copied()
            .filter(|q| q.method.policy == Policy::Fixed)
            .collect();
        let paper: Vec<&Point> = same
            .iter()
            .copied()
            .filter(|q| q.method.is_paper())
            .collect();
        let best_fixed_evals = cheapest_at(&fixed, p.param).map(|q| q.evals_per_ray);
        let paper_evals = cheapest_at(&paper, p.param).map(|q| q.evals_per_ray);
        let evals_with_pilots = p.evals_per_ray + p.pilot_evals as f64 / FRAME_PIXELS;
        rows.push(AutoRow {
            case: p.case.clone(),
            precision: p.precision,
            integrator: p.integrator,
            chosen: p.chosen.clone(),
            asked: p.param,
            delivered: p.err_dir,
            ratio: p.err_dir / p.param,
            evals: p.evals_per_ray,
            best_fixed_evals,
            paper_evals,
            pilot_evals: p.pilot_evals,
            evals_with_pilots,
            over_best: best_fixed_evals.map(|b| evals_with_pilots / b),
            paper_over: paper_evals.map(|x| x / evals_with_pilots),
        });
    }
    rows
}

/// Pixels of the frame the GPU's time per ray is quoted for (640x360).
pub const FRAME_PIXELS: f64 = 640.0 * 360.0;

/// Within this factor of each other (or both below [`GPU_AGREE_FLOOR`] rad), a GPU run's
/// error and its CPU f32 twin's agree.
pub const GPU_AGREE_FACTOR: f64 = 2.0;
pub const GPU_AGREE_FLOOR: f64 = 1e-6;

/// The GPU column of one case: how its errors compare with the CPU f32 twin's (same
/// method and parameter), and what it costs.
#[derive(Debug, Clone, serde::Serialize)]
pub struct GpuRow {
    pub case: String,
    pub runs: usize,
    /// Runs whose error agrees with the twin's ([`GPU_AGREE_FACTOR`]; both failed counts).
    pub agree: usize,
    /// The run that disagrees most: name, GPU error, twin's error.
    pub worst: Option<(String, f64, f64)>,
    /// Medians over the case's runs: GPU ns a ray (a batch on the adapter) and the CPU
    /// f32 twin's (one thread).
    pub gpu_ns_per_ray: f64,
    pub cpu_f32_ns_per_ray: f64,
    /// Per error decade ([`DECADES`]): the cheapest GPU run meeting it.
    pub decades: Vec<GpuDecade>,
}

/// The cheapest GPU run within an error: its name, evals a ray and ms for a 640x360
/// frame of such rays (`None`: no run reaches it).
#[derive(Debug, Clone, serde::Serialize)]
pub struct GpuDecade {
    pub target: f64,
    pub best: Option<(String, f64, f64)>,
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// One [`GpuRow`] per case with GPU runs.
pub fn gpu_rows(run: &AccuracyRun) -> Vec<GpuRow> {
    let mut rows = Vec::new();
    for case in &run.cases {
        let gpu = select(run, &case.name, Precision::Gpu);
        if gpu.is_empty() {
            continue;
        }
        let cpu = select(run, &case.name, Precision::F32);
        let twin = |g: &Point| {
            cpu.iter().copied().find(|c| {
                c.method.integrator == g.method.integrator
                    && c.method.policy == g.method.policy
                    && c.method.exit == g.method.exit
                    && c.param == g.param
            })
        };
        let mut agree = 0;
        let mut worst: Option<(String, f64, f64)> = None;
        let mut worst_gap = 0.0;
        let mut twin_ns = Vec::new();
        for g in &gpu {
            let Some(c) = twin(g) else { continue };
            twin_ns.push(c.ns_per_ray);
            let gap = if g.failed() && c.failed() {
                0.0
            } else if g.failed() || c.failed() {
                f64::INFINITY
            } else if g.err_dir.max(c.err_dir) <= GPU_AGREE_FLOOR {
                0.0
            } else {
                (g.err_dir.max(GPU_AGREE_FLOOR) / c.err_dir.max(GPU_AGREE_FLOOR))
                    .ln()
                    .abs()
            };
            if gap <= GPU_AGREE_FACTOR.ln() {
                agree += 1;
            }
            if gap > worst_gap {
                worst_gap = gap;
                worst = Some((point_name(g), g.err_dir, c.err_dir));
            }
        }
        let decades = DECADES
            .iter()
            .map(|&t| GpuDecade {
                target: t,
                best: cheapest_at(&gpu, t).map(|p| {
                    (
                        point_name(p),
                        p.evals_per_ray,
                        p.ns_per_ray * FRAME_PIXELS * 1e-6,
                    )
                }),
            })
            .collect();
        rows.push(GpuRow {
            case: case.name.clone(),
            runs: gpu.len(),
            agree,
            worst,
            gpu_ns_per_ray: median(gpu.iter().map(|p| p.ns_per_ray).collect()),
            cpu_f32_ns_per_ray: median(twin_ns),
            decades,
        });
    }
    rows
}

fn opt(x: Option<f64>, f: impl Fn(f64) -> String) -> String {
    x.map_or_else(|| "-".into(), f)
}

/// summary.md.
pub fn summary_markdown(run: &AccuracyRun, command: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# grin bench accuracy\n");
    let _ = writeln!(
        s,
        "`{command}` — {} runs over {} cases in {:.1} s.\n",
        run.points.len(),
        run.cases.len(),
        run.seconds
    );
    let _ = writeln!(s, "## References\n");
    let reference_kind = format!("dopri {REFERENCE_TOL:.0e} on the source");
    let references = run.cases.iter().zip(&run.references).map(|(c, r)| {
        let kind = if c.exact.is_some() {
            "exact"
        } else {
            &reference_kind
        };
        vec![
            c.name.to_string(),
            c.rays.len().to_string(),
            kind.to_string(),
            opt(r.numeric_vs_exact, |x| format!("{x:.1e}")),
            opt(c.bake_error, |x| format!("{x:.2e}")),
            opt(c.grid.as_ref().map(|g| g.data_bytes() as f64), |b| {
                format!("{:.2} MB", b / 1e6)
            }),
        ]
    });
    table(
        &mut s,
        &[
            "case",
            "rays",
            "reference",
            "numerical vs exact (rad)",
            "bake's relative error in n",
            "grid in memory",
        ],
        references,
    );
    let _ = writeln!(
        s,
        "\n## The method to use per error decade (cheapest run meeting it)\n"
    );
    let decades = decade_rows(run).into_iter().map(|r| {
        vec![
            r.case.to_string(),
            r.precision.to_string(),
            format!("{:.0e}", r.target),
            r.best.clone().unwrap_or_else(|| "none reaches it".into()),
            opt(r.best_evals, |x| format!("{x:.0}")),
            opt(r.best_err, |x| format!("{x:.1e}")),
            opt(r.paper_evals, |x| format!("{x:.0}")),
            opt(r.paper_ratio, |x| format!("{x:.1}x")),
        ]
    });
    table(
        &mut s,
        &[
            "case",
            "precision",
            "error <=",
            "cheapest",
            "evals/ray",
            "error",
            "paper's method evals/ray",
            "paper / cheapest",
        ],
        decades,
    );
    let _ = writeln!(
        s,
        "\n## The accuracy knob: `step = {{ auto = asked }}` (f64): `auto` (the pilot rays' choice) and error control per length with dopri and sharma\n"
    );
    let knob = auto_rows(run)
        .into_iter()
        .filter(|r| r.precision == "f64" && matches!(r.integrator, "auto" | "dopri" | "sharma"))
        .map(|r| {
            let how = if r.chosen.is_empty() {
                format!("{} per-length", r.integrator)
            } else {
                format!("auto: {}", r.chosen)
            };
            vec![
                r.case.to_string(),
                how,
                format!("{:.0e}", r.asked),
                format!("{:.1e}", r.delivered),
                format!("{:.2}", r.ratio),
                format!("{:.0}", r.evals),
                format!("{}", r.pilot_evals),
                format!("{:.1}", r.evals_with_pilots),
                opt(r.best_fixed_evals, |x| format!("{x:.0}")),
                opt(r.over_best, |x| format!("{x:.2}x")),
                opt(r.paper_evals, |x| format!("{x:.0}")),
                opt(r.paper_over, |x| format!("{x:.1}x")),
            ]
        });
    table(
        &mut s,
        &[
            "case",
            "method",
            "asked (rad)",
            "delivered",
            "delivered / asked",
            "evals/ray",
            "pilot evals",
            "evals/ray with the pilots over a 640x360 frame",
            "cheapest fixed step reaching it",
            "that over the cheapest",
            "paper's method reaching it",
            "paper's over that",
        ],
        knob,
    );
    gpu_markdown(&mut s, run);
    let _ = writeln!(
        s,
        "\n## Measured convergence orders (fixed steps, smooth cases)\n"
    );
    let count = |v: OrderVerdict| run.orders.iter().filter(|o| o.verdict == v).count();
    let fitted = run.orders.len() - count(OrderVerdict::TooFewPoints);
    let _ = writeln!(
        s,
        "The slope of log error against log step over the finest {ORDER_FIT_POINTS} runs with {ORDER_MIN_ERR_F64:.0e} < error < {ORDER_MAX_ERR:.0e} rad (f32: from {ORDER_MIN_ERR_F32:.0e}) whose step was the one asked for (halving it at least {:.2}x the steps: not capped at the field's feature size); \"path\" is the same fit of the optical path's error where the exact solution gives it; expected: the formal order, or the field's own limit where lower. Of {fitted} fitted: {} within {ORDER_TOLERANCE} of the expected order, {} faster, {} slower; {} rows with fewer than 3 runs in the window.\n",
        2.0 * STEPS_FOLLOW_MIN,
        count(OrderVerdict::AsExpected),
        count(OrderVerdict::Faster),
        count(OrderVerdict::Slower),
        count(OrderVerdict::TooFewPoints),
    );
    let orders = run.orders.iter().map(|o| {
        vec![
            o.case.to_string(),
            o.integrator.to_string(),
            o.exit.to_string(),
            o.precision.to_string(),
            o.formal.to_string(),
            o.expected.to_string(),
            opt(o.measured, |x| format!("{x:.2}")),
            opt(o.measured_opl, |x| format!("{x:.2}")),
            o.verdict.name().to_string(),
            o.steps.clone(),
        ]
    });
    table(
        &mut s,
        &[
            "case",
            "integrator",
            "exit",
            "precision",
            "formal",
            "expected",
            "measured",
            "path",
            "verdict",
            "steps a ray fitted",
        ],
        orders,
    );
    let failed = run.points.iter().filter(|p| p.failed()).count();
    let _ = writeln!(
        s,
        "\n{failed} of {} runs lost rays (status other than `exited`); they are in accuracy.csv with infinite error and not on the charts.",
        run.points.len()
    );
    s
}

/// The GPU column's section of summary.md.
fn gpu_markdown(s: &mut String, run: &AccuracyRun) {
    let _ = writeln!(s, "\n## The GPU column\n");
    let Some(adapter) = &run.gpu.adapter else {
        let why = run.gpu.skipped.as_deref().unwrap_or("no GPU runs");
        let _ = writeln!(s, "No GPU runs: {why}.");
        return;
    };
    let _ = writeln!(
        s,
        "On `{adapter}`: the render kernel's own `march_medium` (f32) on the cases with a baked field, the same rays and error measure; {} pipelines, {:.1} s. A run *agrees* with its CPU f32 twin (same method and parameter) when their errors are within {GPU_AGREE_FACTOR}x (or both below {GPU_AGREE_FLOOR:.0e} rad, or both failed). GPU ns a ray: the kernel's time over a batch of copies of the case's rays (about {GPU_TIMED_EVALS:.0e} field evaluations); CPU: one thread. Frame ms: a 640x360 frame of such rays.\n",
        run.gpu.pipelines,
        run.gpu.seconds,
        GPU_TIMED_EVALS = crate::accuracy::GPU_TIMED_EVALS
    );
    let rows = gpu_rows(run).into_iter().map(|r| {
        let decade = |i: usize| match &r.decades[i].best {
            Some((n, e, ms)) => format!("{n}: {e:.0} evals, {ms:.0} ms"),
            None => "none reaches it".into(),
        };
        vec![
            r.case.clone(),
            format!("{}/{}", r.agree, r.runs),
            r.worst
                .as_ref()
                .map_or("-".into(), |(n, g, c)| format!("{n}: {g:.1e} vs {c:.1e}")),
            format!("{:.0}", r.gpu_ns_per_ray),
            format!("{:.0}", r.cpu_f32_ns_per_ray),
            decade(0),
            decade(1),
        ]
    });
    table(
        s,
        &[
            "case",
            "agree with the f32 twin",
            "widest gap (gpu vs twin, rad)",
            "gpu ns/ray (median)",
            "cpu f32 ns/ray (median)",
            "cheapest <= 1e-2 (frame ms)",
            "cheapest <= 1e-4 (frame ms)",
        ],
        rows,
    );
}

fn csv_text<T: serde::Serialize>(rows: &[T]) -> anyhow::Result<Vec<u8>> {
    let mut w = csv::Writer::from_writer(Vec::new());
    for r in rows {
        w.serialize(r)?;
    }
    w.into_inner()
        .map_err(|e| anyhow::Error::msg(e.to_string()))
}

fn stage_bytes(path: &Path, bytes: Vec<u8>) -> anyhow::Result<Staged> {
    Ok(stage_writer(path, move |w| w.write_all(&bytes))?)
}

/// Write everything into `dir` (created if missing); returns the files written.
pub fn write_accuracy(run: &AccuracyRun, dir: &Path, command: &str) -> anyhow::Result<Vec<String>> {
    std::fs::create_dir_all(dir).map_err(|e| {
        anyhow::Error::msg(format!(
            "{}: cannot create: {}",
            dir.display(),
            grin_output::plain(&e)
        ))
    })?;
    let mut staged = Vec::new();
    let mut names = Vec::new();
    let mut add = |name: String, bytes: Vec<u8>| -> anyhow::Result<()> {
        staged.push(stage_bytes(&dir.join(&name), bytes)?);
        names.push(name);
        Ok(())
    };
    add("accuracy.csv".into(), csv_text(&run.points)?)?;
    add("orders.csv".into(), csv_text(&run.orders)?)?;
    add("auto.csv".into(), csv_text(&auto_rows(run))?)?;
    add(
        "summary.md".into(),
        summary_markdown(run, command).into_bytes(),
    )?;
    for case in &run.cases {
        for precision in Precision::ALL {
            if select(run, &case.name, precision).is_empty() {
                continue;
            }
            let chart = case_chart(run, &case.name, precision);
            let stem = format!("chart-{}-{}", case.name, precision.name());
            add(format!("{stem}.svg"), svg(&chart)?.into_bytes())?;
            add(format!("{stem}.png"), png(&chart)?)?;
        }
    }
    commit(staged)?;
    Ok(names)
}

/// Write stability.md and stability.csv into `dir`; returns the files written.
pub fn write_stability(
    m: &crate::stability::Matrix,
    dir: &Path,
    command: &str,
) -> anyhow::Result<Vec<String>> {
    std::fs::create_dir_all(dir).map_err(|e| {
        anyhow::Error::msg(format!(
            "{}: cannot create: {}",
            dir.display(),
            grin_output::plain(&e)
        ))
    })?;
    let staged = vec![
        stage_bytes(&dir.join("stability.csv"), csv_text(&m.cells)?)?,
        stage_bytes(
            &dir.join("stability.md"),
            crate::stability::markdown(m, command).into_bytes(),
        )?,
    ];
    commit(staged)?;
    Ok(vec!["stability.csv".into(), "stability.md".into()])
}

/// A Markdown table: the header, its separator, one line per row.
fn table(s: &mut String, header: &[&str], rows: impl IntoIterator<Item = Vec<String>>) {
    let _ = writeln!(s, "| {} |", header.join(" | "));
    let _ = writeln!(s, "|{}", "---|".repeat(header.len()));
    for row in rows {
        let _ = writeln!(s, "| {} |", row.join(" | "));
    }
}
