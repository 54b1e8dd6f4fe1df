//! The GPU ray table (`grin_gpu::march`, the GPU column of `grin bench accuracy`) against
//! its CPU twin: the same rays through the same baked fields, traced by the render
//! kernel's `march_medium` and by `grin_trace::trace_ray::<f32>`.

#![allow(clippy::unwrap_used)]

mod harness;

use std::path::Path;
use std::sync::Arc;

use glam::DVec3;
use grin_field::baked::{BakedField, Interp};
use grin_gpu::GpuRayTracer;
use grin_render::settings::TraceSettings;
use grin_scene::{ExitMethod, IntegratorKind, StepSpec, load_scene};
use grin_trace::{RayStatus, trace_ray};

fn baked(name: &str, resolution: usize, interp: Interp) -> Arc<BakedField> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../data/scenes/{name}.toml"));
    let scene = load_scene(&path).unwrap();
    let b = harness::baked(&scene, path.parent().unwrap(), resolution).unwrap();
    Arc::new(Arc::try_unwrap(b).unwrap().with_interp(interp))
}

/// A fan of rays from outside the bounds through the medium's centre region.
fn rays(field: &BakedField, count: usize) -> Vec<(DVec3, DVec3)> {
    use grin_field::IndexField;
    let b = field.bounds();
    let (c, r) = (b.center(), b.radius());
    (0..count)
        .map(|i| {
            let f = i as f64 / count as f64;
            let offset = DVec3::new(0.8 * r * (f - 0.5), 0.3 * r * (6.0 * f).sin(), 0.0);
            (
                c + offset - DVec3::Z * 3.0 * r,
                DVec3::new(0.02 * f, 0.0, 1.0),
            )
        })
        .collect()
}

fn settings(integrator: IntegratorKind, step: StepSpec, exit: ExitMethod) -> TraceSettings {
    TraceSettings {
        integrator,
        step,
        max_steps: 100_000,
        exit,
        macro_cells: true,
        accuracy: grin_scene::DEFAULT_AUTO_ACCURACY,
        estimate_limit: grin_scene::DEFAULT_AUTO_ACCURACY,
        opl_control: false,
    }
}

#[test]
fn gpu_ray_table_matches_the_cpu_f32_twin() {
    let Some(ctx) = harness::context("gpu_ray_table_matches_the_cpu_f32_twin") else {
        return;
    };
    let lens = baked("luneburg", 48, Interp::Tricubic);
    let plume = baked("plume", 48, Interp::Trilinear);
    let mut gpu = GpuRayTracer::new(&ctx, Arc::clone(&lens)).unwrap();
    let methods = [
        settings(
            IntegratorKind::Rk4,
            StepSpec::Fixed(0.05),
            ExitMethod::Hermite,
        ),
        settings(
            IntegratorKind::Sharma,
            StepSpec::Fixed(0.05),
            ExitMethod::Bisection,
        ),
        settings(
            IntegratorKind::Adaptive,
            StepSpec::Auto(1e-4),
            ExitMethod::Hermite,
        ),
    ];
    let mut compared = 0;
    let (mut worst_angle, mut worst_evals) = (0.0f64, 0.0f64);
    for field in [&lens, &plume] {
        gpu.set_field(Arc::clone(field)).unwrap();
        let rays = rays(field, 40);
        for s in &methods {
            let (out, seconds) = gpu.trace(s, &rays, 1).unwrap();
            assert_eq!(out.len(), rays.len());
            assert!(seconds > 0.0);
            for ((o, d), g) in rays.iter().zip(&out) {
                let c = trace_ray::<f32>(field.as_ref(), s, *o, *d);
                let status = RayStatus::ALL[g.status as usize];
                assert_eq!(status, c.status, "{s:?} ray {o} {d}");
                if !c.status.left() {
                    continue;
                }
                compared += 1;
                let angle = g.direction.angle_between(c.direction);
                worst_angle = worst_angle.max(angle);
                assert!(
                    angle < 2e-5,
                    "{s:?} ray from {o}: direction {angle} rad apart"
                );
                assert!(
                    (g.position - c.position).length() < 1e-4,
                    "{s:?} ray from {o}: exit {} vs {}",
                    g.position,
                    c.position
                );
                assert!((g.opl - c.opl).abs() < 1e-4 * c.opl.max(1.0));
                // The same steps and field samples, up to an f32 rounding that moves a
                // step across a face or an adaptive acceptance.
                let (ge, ce) = (f64::from(g.evals), c.evals as f64);
                worst_evals = worst_evals.max((ge - ce).abs() / ce);
                assert!((ge - ce).abs() <= 0.1 * ce + 8.0, "evals {ge} vs {ce}");
            }
        }
    }
    eprintln!(
        "{compared} rays: worst direction difference {worst_angle:.2e} rad, evals {:.1}% apart",
        100.0 * worst_evals
    );
    assert!(compared > 150, "{compared} rays compared");
    // One pipeline per method (the bounds' shape is a constant too: sphere and box).
    assert_eq!(gpu.pipelines_compiled(), 2 * methods.len());
    // Copies trace the same rays: the first copy's results are returned.
    gpu.set_field(Arc::clone(&lens)).unwrap();
    let rays = rays(&lens, 8);
    let (one, _) = gpu.trace(&methods[0], &rays, 1).unwrap();
    let (many, _) = gpu.trace(&methods[0], &rays, 50).unwrap();
    assert_eq!(one, many);
}

/// lavapipe (Mesa's gallivm) stops all loops of a shader invocation after 65535
/// iterations in all (`LP_MAX_TGSI_LOOP_ITERATIONS`). The tricubic sample's 4x4x4 loops
/// spent ~20 a sample and the Dormand-Prince stages 27 a step, so rays of more than ~2300
/// tricubic samples or ~1900 dopri steps ended `error` on the GPU (the bench's GPU column
/// found it: every run below R/256 on a tricubic grid). The tricubic sum is written out
/// now and the stages run in one loop of 6: ~3 iterations a step are left, 9 with dopri
/// (~21,800 steps a ray on lavapipe, ~7,000 dopri steps; no limit on a GPU).
#[test]
fn long_rays_are_not_cut_short_by_lavapipes_loop_limit() {
    let Some(ctx) = harness::context("long_rays_are_not_cut_short_by_lavapipes_loop_limit") else {
        return;
    };
    let lens = baked("luneburg", 48, Interp::Tricubic);
    let mut gpu = GpuRayTracer::new(&ctx, Arc::clone(&lens)).unwrap();
    let rays = rays(&lens, 4);
    for (s, min_steps) in [
        // ~2000 steps, ~8000 tricubic samples.
        (
            settings(
                IntegratorKind::Rk4,
                StepSpec::Fixed(1.0 / 1024.0),
                ExitMethod::Hermite,
            ),
            1900,
        ),
        // ~4000 Dormand-Prince steps.
        (
            settings(
                IntegratorKind::Adaptive,
                StepSpec::Fixed(1.0 / 2048.0),
                ExitMethod::Hermite,
            ),
            3800,
        ),
    ] {
        let (out, _) = gpu.trace(&s, &rays, 1).unwrap();
        for ((o, d), g) in rays.iter().zip(&out) {
            let c = trace_ray::<f32>(lens.as_ref(), &s, *o, *d);
            // Left the medium (`degraded` where thousands of f32 steps drift |T| from n
            // by more than the 1e-4 rad asked for), the same on both backends.
            assert!(c.status.left(), "{:?}", c.status);
            assert!(c.steps >= min_steps, "{} steps", c.steps);
            assert_eq!(
                RayStatus::ALL[g.status as usize],
                c.status,
                "{s:?}: GPU status {} after {} steps",
                g.status,
                g.steps
            );
            assert_eq!(g.steps, c.steps);
            assert!(g.direction.angle_between(c.direction) < 2e-5);
        }
    }
}

/// Rays entering the lens steeply off-centre (h = 0.85..0.95 R), whose f32 entry point
/// (computed on the GPU from a start 3 R away) lands just outside the sphere about half
/// the time: the nudge inside keeps them on their own line. Moved along the normal (by
/// ~1e-6 R in f32), they were shifted sideways: GPU worst 3.0e-6 rad from the f64 trace
/// over the same grid, 1.1e-6 with the nudge along the ray, 4.8e-7 once lavapipe stopped
/// compiling the compensated summation away (`FrameParams::roundoff_one`); the twin 2.9e-7.
#[test]
fn entry_nudges_keep_rays_on_their_own_line() {
    let Some(ctx) = harness::context("entry_nudges_keep_rays_on_their_own_line") else {
        return;
    };
    let lens = baked("luneburg", 64, Interp::Tricubic);
    let mut gpu = GpuRayTracer::new(&ctx, Arc::clone(&lens)).unwrap();
    let rays: Vec<(DVec3, DVec3)> = (0..64)
        .map(|i| {
            let h = 0.85 + 0.1 * i as f64 / 63.0;
            let side = if i % 2 == 0 { 1.0 } else { -1.0 };
            let a = 0.37 * i as f64;
            (
                DVec3::new(side * h * a.cos(), side * h * a.sin(), -3.0),
                DVec3::Z,
            )
        })
        .collect();
    let s = settings(
        IntegratorKind::Rk4,
        StepSpec::Fixed(0.05),
        ExitMethod::Hermite,
    );
    let (out, _) = gpu.trace(&s, &rays, 1).unwrap();
    let (mut worst_gpu, mut worst_twin) = (0.0f64, 0.0f64);
    for ((o, d), g) in rays.iter().zip(&out) {
        let reference = trace_ray::<f64>(lens.as_ref(), &s, *o, *d);
        let twin = trace_ray::<f32>(lens.as_ref(), &s, *o, *d);
        assert_eq!(
            RayStatus::ALL[g.status as usize],
            twin.status,
            "ray from {o}"
        );
        assert!(twin.status.left(), "ray from {o}: {:?}", twin.status);
        worst_gpu = worst_gpu.max(g.direction.angle_between(reference.direction));
        worst_twin = worst_twin.max(twin.direction.angle_between(reference.direction));
    }
    eprintln!("exit direction vs f64: GPU worst {worst_gpu:.2e} rad, twin {worst_twin:.2e}");
    assert!(worst_twin < 4e-7, "twin {worst_twin:.2e} rad");
    assert!(
        worst_gpu < 1.6e-6,
        "GPU {worst_gpu:.2e} rad (twin {worst_twin:.2e})"
    );
}

/// A march split over dispatches (its state kept on the device between them) is the
/// whole march: the same steps in the same arithmetic, bit for bit, whatever the budget
/// of steps a dispatch allows.
#[test]
fn a_march_split_over_dispatches_is_the_whole_march() {
    let Some(ctx) = harness::context("a_march_split_over_dispatches_is_the_whole_march") else {
        return;
    };
    let lens = baked("luneburg", 48, Interp::Tricubic);
    let mut gpu = GpuRayTracer::new(&ctx, Arc::clone(&lens)).unwrap();
    let mut rays = rays(&lens, 24);
    // Rays entering at grazing incidence (reflections at the surface, exit searches).
    rays.extend((0..8).map(|i| {
        let h = 0.9 + 0.0124 * f64::from(i);
        (DVec3::new(h, 0.0, -3.0), DVec3::Z)
    }));
    for s in [
        settings(
            IntegratorKind::Rk4,
            StepSpec::Fixed(1.0 / 512.0),
            ExitMethod::Hermite,
        ),
        settings(
            IntegratorKind::Adaptive,
            StepSpec::Fixed(1.0 / 256.0),
            ExitMethod::Bisection,
        ),
    ] {
        gpu.set_steps_per_dispatch(u32::MAX);
        let (whole, _) = gpu.trace(&s, &rays, 1).unwrap();
        assert_eq!(gpu.last_dispatches(), 1);
        let most = whole.iter().map(|r| r.steps).max().unwrap();
        assert!(most > 40, "{most} steps at most: too few to split");
        for budget in [1, 7, 40] {
            gpu.set_steps_per_dispatch(budget);
            let (split, _) = gpu.trace(&s, &rays, 1).unwrap();
            assert!(
                gpu.last_dispatches() >= most / budget,
                "{} dispatches of {budget} steps for {most} steps",
                gpu.last_dispatches()
            );
            assert_eq!(split, whole, "{s:?} split every {budget} steps");
        }
    }
}

/// Rays of 40,000+ steps (rk4 at 2.5e-5 R) through the GPU's bake of the Luneburg lens:
/// through the centre, and tangent to the surface from inside at 0.9999 R (trapped
/// there past max_steps).
/// Marched whole in one invocation, lavapipe's loop limit (65,535 loop iterations in
/// all, ~3 a step) ended them `error` after ~21,800 steps; split over dispatches they
/// leave as their CPU twins do.
#[test]
fn rays_past_lavapipes_loop_limit_leave_as_their_cpu_twin() {
    let Some(ctx) = harness::context("rays_past_lavapipes_loop_limit_leave_as_their_cpu_twin")
    else {
        return;
    };
    let lens = baked("luneburg", 100, Interp::Trilinear);
    let mut gpu = GpuRayTracer::new(&ctx, Arc::clone(&lens)).unwrap();
    let rays = [
        (DVec3::new(0.0, 0.0, -3.0), DVec3::Z),
        (DVec3::new(0.9999, 0.0, 0.0), DVec3::Y),
    ];
    let mut s = settings(
        IntegratorKind::Rk4,
        StepSpec::Fixed(2.5e-5),
        ExitMethod::Hermite,
    );
    s.max_steps = 400_000;
    let (out, _) = gpu.trace(&s, &rays, 1).unwrap();
    for ((o, d), g) in rays.iter().zip(&out) {
        let c = trace_ray::<f32>(lens.as_ref(), &s, *o, *d);
        eprintln!(
            "CPU twin: {:?} after {} steps; GPU: {} after {} steps, {} dispatches, {:.2e} rad apart",
            c.status,
            c.steps,
            g.status,
            g.steps,
            gpu.last_dispatches(),
            g.direction.angle_between(c.direction)
        );
        assert!(c.steps > 40_000, "{} steps: not a long ray", c.steps);
        assert_eq!(RayStatus::ALL[g.status as usize], c.status);
        assert_eq!(g.steps, c.steps);
        assert!(g.direction.angle_between(c.direction) < 1e-5);
    }
    // Through the centre the ray leaves (79,997 steps); the tangent one is trapped
    // beyond max_steps on both backends (its orbit hugs the bake's surface).
    let c = trace_ray::<f32>(lens.as_ref(), &s, rays[0].0, rays[0].1);
    assert!(c.status.left(), "{:?}", c.status);
    assert!(gpu.last_dispatches() > 40);
}

/// A sparse bake (`grin bake --sparse`) traced by the ray table: the same statuses,
/// exits and evaluations as its CPU f32 twin, as the dense grids above.
#[test]
fn gpu_ray_table_marches_sparse_bakes_as_its_cpu_twin() {
    use grin_field::IndexField;
    use grin_field::sparse::bake::{SparseOptions, bake_sparse};
    let Some(ctx) = harness::context("gpu_ray_table_marches_sparse_bakes_as_its_cpu_twin") else {
        return;
    };
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/scenes/plume.toml");
    let scene = load_scene(&path).unwrap();
    let source = harness::build_field(&scene, path.parent().unwrap()).unwrap();
    let opts = SparseOptions {
        error_budget: 1e-3,
        ..SparseOptions::default()
    };
    let (sparse, report) = bake_sparse(source.as_ref(), &opts, &|_, _, _| {}).unwrap();
    assert!(report.active_bricks < report.total_bricks, "{report:?}");
    let sparse = Arc::new(sparse);
    let mut gpu = GpuRayTracer::new(&ctx, Arc::clone(&sparse)).unwrap();
    let (c, r) = (sparse.bounds().center(), sparse.bounds().radius());
    let rays: Vec<(DVec3, DVec3)> = (0..48)
        .map(|i| {
            let f = i as f64 / 48.0;
            let offset = DVec3::new(0.8 * r * (f - 0.5), 0.3 * r * (6.0 * f).sin(), 0.0);
            (
                c + offset - DVec3::Z * 3.0 * r,
                DVec3::new(0.02 * f, 0.0, 1.0),
            )
        })
        .collect();
    let mut compared = 0;
    for s in [
        settings(
            IntegratorKind::Rk4,
            StepSpec::Fixed(0.05 * r),
            ExitMethod::Hermite,
        ),
        settings(
            IntegratorKind::Adaptive,
            StepSpec::Auto(1e-4),
            ExitMethod::Hermite,
        ),
    ] {
        let (out, _) = gpu.trace(&s, &rays, 1).unwrap();
        for ((o, d), g) in rays.iter().zip(&out) {
            let c = trace_ray::<f32>(sparse.as_ref(), &s, *o, *d);
            assert_eq!(
                RayStatus::ALL[g.status as usize],
                c.status,
                "{s:?} ray {o} {d}"
            );
            if !c.status.left() {
                continue;
            }
            compared += 1;
            let angle = g.direction.angle_between(c.direction);
            assert!(
                angle < 2e-5,
                "{s:?} ray from {o}: direction {angle} rad apart"
            );
            assert!((g.position - c.position).length() < 1e-4 * r.max(1.0));
            assert!((g.opl - c.opl).abs() < 1e-4 * c.opl.max(1.0));
            let (ge, ce) = (f64::from(g.evals), c.evals as f64);
            assert!((ge - ce).abs() <= 0.1 * ce + 8.0, "evals {ge} vs {ce}");
        }
    }
    assert!(compared > 60, "{compared} rays compared");
}
