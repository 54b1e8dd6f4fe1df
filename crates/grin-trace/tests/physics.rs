//! The tracer against exact solutions: Luneburg focus, Maxwell fish-eye imaging, GRIN rod
//! period, linear n^2 parabolas, convergence orders, invariants, refraction at a
//! constant-index ball and box, exit points on the surface, the f32 path and bad input.
//!
//! One concept, one file: a test per exact solution or invariant, each self-contained.

mod common;

use std::f64::consts::PI;

use common::{Profile, TestField, golden_min, log_slope};
use glam::DVec3;
use grin_field::{IndexField, Real};
use grin_render::settings::TraceSettings;
use grin_scene::{ExitMethod, IntegratorKind, StepSpec};
use grin_trace::integrate::{self, RayState};
use grin_trace::step::StepController;
use grin_trace::{Control, RayResult, RayStatus, Segment, trace_ray, trace_ray_observed};

fn settings(integrator: IntegratorKind, step: StepSpec, exit: ExitMethod) -> TraceSettings {
    TraceSettings {
        integrator,
        step,
        max_steps: 1_000_000,
        exit,
        macro_cells: false,
        accuracy: grin_scene::DEFAULT_AUTO_ACCURACY,
        estimate_limit: grin_scene::DEFAULT_AUTO_ACCURACY,
        opl_control: false,
    }
}

fn luneburg() -> TestField {
    TestField::sphere(
        Profile::Luneburg {
            c: DVec3::ZERO,
            radius: 1.0,
        },
        DVec3::ZERO,
        1.0,
        1.0,
    )
}

/// A parallel beam along +z from the plane z = -2 filling the disk of radius 0.95 R:
/// 13 x 13 grid points inside it (>= 100 rays).
fn beam() -> Vec<DVec3> {
    const GRID: i32 = 13;
    const DISK: f64 = 0.95;
    let mut out = Vec::new();
    for i in 0..GRID {
        for j in 0..GRID {
            let x = -DISK + 2.0 * DISK * i as f64 / (GRID - 1) as f64;
            let y = -DISK + 2.0 * DISK * j as f64 / (GRID - 1) as f64;
            if x * x + y * y <= DISK * DISK {
                out.push(DVec3::new(x, y, -2.0));
            }
        }
    }
    out
}

/// Worst distance of the beam's exit points from the antipodal focus (0, 0, R), and the
/// spread of optical path lengths from the plane z = -2 to the focus.
fn luneburg_focus<R: Real>(s: &TraceSettings) -> (f64, f64, usize) {
    let field = luneburg();
    let focus = DVec3::new(0.0, 0.0, 1.0);
    let rays = beam();
    let mut worst = 0.0f64;
    let (mut opl_min, mut opl_max) = (f64::INFINITY, f64::NEG_INFINITY);
    for o in &rays {
        let res = trace_ray::<R>(&field, s, *o, DVec3::Z);
        assert_eq!(res.status, RayStatus::Exited, "ray from {o}: {res:?}");
        worst = worst.max((res.position - focus).length());
        // Ambient path from the wavefront z = -2 to the entry point, plus the inside path.
        let entry_z = -(1.0 - o.x * o.x - o.y * o.y).sqrt();
        let opl = (entry_z + 2.0) + res.opl;
        opl_min = opl_min.min(opl);
        opl_max = opl_max.max(opl);
    }
    (worst, opl_max - opl_min, rays.len())
}

#[test]
fn luneburg_beam_focuses_at_antipode_adaptive() {
    for exit in [ExitMethod::Hermite, ExitMethod::Bisection] {
        let s = settings(
            IntegratorKind::Adaptive,
            StepSpec::Adaptive {
                tolerance: 1e-10,
                initial: None,
            },
            exit,
        );
        let (worst, opl_spread, n) = luneburg_focus::<f64>(&s);
        assert!(n >= 100);
        assert!(worst <= 1e-7, "{exit:?}: worst focus error {worst:e}");
        // Fermat: a perfect lens has equal optical paths from the wavefront to the focus.
        assert!(opl_spread <= 1e-7, "{exit:?}: opl spread {opl_spread:e}");
    }
}

/// Sharma at 256 steps per quarter orbit: the quarter orbit is t = pi R / 2, so a fixed
/// world step ds = (pi R / 2) / 256 gives h = ds / n <= (pi R / 2) / 256 in t (n >= 1).
#[test]
fn luneburg_beam_focuses_at_antipode_sharma_256() {
    let ds = (PI / 2.0) / 256.0;
    for exit in [ExitMethod::Hermite, ExitMethod::Bisection] {
        let s = settings(IntegratorKind::Sharma, StepSpec::Fixed(ds), exit);
        let (worst, opl_spread, _) = luneburg_focus::<f64>(&s);
        assert!(worst <= 1e-7, "{exit:?}: worst focus error {worst:e}");
        assert!(opl_spread <= 1e-7, "{exit:?}: opl spread {opl_spread:e}");
    }
}

#[test]
fn luneburg_step_doubling_and_heuristic() {
    // Error control by step doubling for a fixed-order integrator.
    let s = settings(
        IntegratorKind::Sharma,
        StepSpec::Adaptive {
            tolerance: 1e-10,
            initial: None,
        },
        ExitMethod::Hermite,
    );
    let (worst, _, _) = luneburg_focus::<f64>(&s);
    assert!(worst <= 1e-7, "step doubling: worst focus error {worst:e}");
    // The paper's heuristic with a small minimum step converges to the focus too.
    let s = settings(
        IntegratorKind::Sharma,
        StepSpec::Heuristic {
            min: 0.002,
            max: 0.01,
            amplitude: None,
        },
        ExitMethod::Hermite,
    );
    let (worst, _, _) = luneburg_focus::<f64>(&s);
    assert!(worst <= 1e-8, "heuristic: worst focus error {worst:e}");
}

#[test]
fn luneburg_axial_opl_and_length() {
    // Along the diameter: length 2R, opl = integral of sqrt(2 - z^2) over [-1, 1] = 1 + pi/2.
    let s = settings(
        IntegratorKind::Sharma,
        StepSpec::Fixed(0.01),
        ExitMethod::Hermite,
    );
    let res = trace_ray::<f64>(&luneburg(), &s, DVec3::new(0.0, 0.0, -3.0), DVec3::Z);
    assert_eq!(res.status, RayStatus::Exited);
    assert!((res.length - 2.0).abs() < 1e-10, "length {}", res.length);
    assert!((res.opl - (1.0 + PI / 2.0)).abs() < 1e-9, "opl {}", res.opl);
    assert!(
        (res.transmittance - 1.0).abs() < 1e-12,
        "index-matched surface reflects nothing"
    );
}

#[test]
fn heuristic_step_lerps_between_min_and_max() {
    let g = DVec3::new(0.0, 2.0, 0.0);
    let along = StepController::heuristic_ds(0.1, 0.5, 2.0, DVec3::Y, g);
    let across = StepController::heuristic_ds(0.1, 0.5, 2.0, DVec3::X, g);
    let half = StepController::heuristic_ds(0.1, 0.5, 4.0, DVec3::Y, g);
    assert!((along - 0.1).abs() < 1e-15);
    assert!((across - 0.5).abs() < 1e-15);
    assert!((half - 0.3).abs() < 1e-15);
}

/// Maxwell fish-eye n = n0 / (1 + (r/a)^2): every ray from a point P inside passes through
/// its image P' = -a^2 P / |P|^2 (outside radius a), measured as the closest approach of
/// the dense output.
fn fisheye_image_error<R: Real>(s: &TraceSettings) -> f64 {
    let a = 1.0;
    let field = TestField::sphere(Profile::FishEye { n0: 2.0, a }, DVec3::ZERO, 20.0, 1.0);
    let p = DVec3::new(0.3, 0.1, -0.2);
    let image = -p * (a * a / p.length_squared());
    let chord = (image - p).normalize();
    // Directions at 50..130 degrees to the chord P P' (circles of moderate radius).
    let u = chord.any_orthonormal_vector();
    let v = chord.cross(u);
    let mut worst = 0.0f64;
    let mut count = 0;
    for i in 0..5 {
        let theta = (50.0 + 20.0 * i as f64).to_radians();
        for k in 0..4 {
            let phi = k as f64 * PI / 2.0 + 0.3;
            let dir = chord * theta.cos() + (u * phi.cos() + v * phi.sin()) * theta.sin();
            let mut best = f64::INFINITY;
            let mut was_near = false;
            let res = trace_ray_observed::<R>(&field, s, p, dir, &mut |seg: &Segment| {
                let near = (seg.r0 - image).length().min((seg.r1 - image).length()) < 0.1;
                if near {
                    was_near = true;
                    let (_, d) = golden_min(0.0, seg.h, |tau| (seg.point(tau) - image).length());
                    best = best.min(d);
                    Control::Continue
                } else if was_near {
                    Control::Stop
                } else {
                    Control::Continue
                }
            });
            assert_eq!(
                res.status,
                RayStatus::Absorbed,
                "ray {dir} never passed the image"
            );
            worst = worst.max(best);
            count += 1;
        }
    }
    assert_eq!(count, 20);
    worst
}

#[test]
fn maxwell_fisheye_images_point() {
    let s = settings(
        IntegratorKind::Sharma,
        StepSpec::Fixed(1e-3),
        ExitMethod::Hermite,
    );
    let err = fisheye_image_error::<f64>(&s);
    assert!(err <= 1e-7, "fish-eye image error {err:e} a");
}

/// GRIN rod n^2 = n0^2 (1 - a^2 rho^2): x is harmonic in t with omega = n0 a and z = beta t,
/// so the z-period is 2 pi beta / (n0 a), beta = n dz/ds.
fn rod_period_error<R: Real>(ds: f64) -> f64 {
    let (n0, a) = (1.5, 0.5);
    let field = TestField::cuboid(
        Profile::GrinRod { n0, a },
        DVec3::new(-1.0, -1.0, 0.0),
        DVec3::new(1.0, 1.0, 40.0),
        1.0,
    );
    let o = DVec3::new(0.3, 0.0, 0.5);
    let d = DVec3::new(0.1, 0.05, 1.0).normalize();
    let beta = field.sample(o).n * d.z;
    let exact = 2.0 * PI * beta / (n0 * a);
    let s = settings(
        IntegratorKind::Sharma,
        StepSpec::Fixed(ds),
        ExitMethod::Hermite,
    );
    let mut crossings = Vec::new();
    let res = trace_ray_observed::<R>(&field, &s, o, d, &mut |seg: &Segment| {
        if seg.r0.x < 0.0 && seg.r1.x >= 0.0 {
            // Upward zero of x on the dense output, by bisection.
            let (mut lo, mut hi) = (0.0, seg.h);
            for _ in 0..100 {
                let mid = 0.5 * (lo + hi);
                if seg.point(mid).x < 0.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            crossings.push(seg.point(0.5 * (lo + hi)).z);
        }
        Control::Continue
    });
    assert_eq!(res.status, RayStatus::Exited);
    assert!(crossings.len() >= 3, "only {} periods", crossings.len());
    let measured = (crossings[crossings.len() - 1] - crossings[0]) / (crossings.len() - 1) as f64;
    (measured - exact).abs()
}

#[test]
fn grin_rod_period() {
    let err = rod_period_error::<f64>(2e-3);
    assert!(err <= 1e-7, "rod z-period error {err:e}");
}

/// Linear n^2 = n0^2 + k y: D = (0, k/2, 0), r(t) = r0 + T0 t + k/4 t^2 y.
#[test]
fn linear_n2_is_an_exact_parabola() {
    let (n0, k) = (1.2, 0.3);
    let field = TestField::cuboid(
        Profile::LinearN2 { n0, k },
        DVec3::splat(-1.0),
        DVec3::splat(1.0),
        1.2,
    );
    let o = DVec3::new(-0.9, -0.5, 0.1);
    let d = DVec3::new(1.0, 0.2, 0.05).normalize();
    let t0 = d * field.sample(o).n;
    let exact = |t: f64| o + t0 * t + DVec3::Y * (0.25 * k * t * t);
    for kind in [IntegratorKind::Sharma, IntegratorKind::Rk4] {
        for exit in [ExitMethod::Hermite, ExitMethod::Bisection] {
            let s = settings(kind, StepSpec::Fixed(0.05), exit);
            let mut t_acc = 0.0;
            let mut worst = 0.0f64;
            let mut worst_t = 0.0f64;
            let res = trace_ray_observed::<f64>(&field, &s, o, d, &mut |seg: &Segment| {
                t_acc += seg.h;
                worst = worst.max((seg.r1 - exact(t_acc)).length());
                worst_t = worst_t.max((seg.t1 - (t0 + DVec3::Y * (0.5 * k * t_acc))).length());
                Control::Continue
            });
            assert_eq!(res.status, RayStatus::Exited);
            assert!(
                worst <= 1e-12,
                "{kind:?} {exit:?}: path off the parabola by {worst:e}"
            );
            assert!(worst_t <= 1e-12, "{kind:?} {exit:?}: T off by {worst_t:e}");
            // The exit face is x = 1: t* = (1 - x0) / T0x.
            let p_exact = exact((1.0 - o.x) / t0.x);
            let err = (res.position - p_exact).length();
            assert!(err <= 1e-10, "{kind:?} {exit:?}: exit point off by {err:e}");
        }
    }
}

/// Integrate with fixed h in t from a fixed start in a smooth Gaussian blob.
fn integrate_fixed(kind: IntegratorKind, field: &TestField, steps: u32, t_end: f64) -> DVec3 {
    let r0 = DVec3::new(-1.0, 0.0, 0.0);
    let mut s = RayState::<f64> {
        r: r0,
        t: DVec3::new(1.0, 0.3, 0.1).normalize() * field.sample(r0).n,
    };
    let h = t_end / steps as f64;
    for _ in 0..steps {
        let d0 = field.sample(s.r).n_grad_n();
        s = integrate::step(kind, field, s, d0, h).state;
    }
    s.r
}

#[test]
fn convergence_orders() {
    let field = TestField::sphere(
        Profile::Blob {
            c: DVec3::new(0.2, -0.1, 0.3),
            amp: 0.3,
            s: 0.8,
        },
        DVec3::ZERO,
        10.0,
        1.0,
    );
    let t_end = 2.0;
    let reference = integrate_fixed(IntegratorKind::Adaptive, &field, 8192, t_end);
    let cases: [(IntegratorKind, f64, &[u32]); 6] = [
        (IntegratorKind::Euler, 1.0, &[64, 128, 256, 512, 1024]),
        (
            IntegratorKind::SymplecticEuler,
            1.0,
            &[64, 128, 256, 512, 1024],
        ),
        (IntegratorKind::Verlet, 2.0, &[16, 32, 64, 128, 256]),
        (IntegratorKind::Sharma, 4.0, &[16, 32, 64, 128, 256]),
        (IntegratorKind::Rk4, 4.0, &[16, 32, 64, 128, 256]),
        (IntegratorKind::Adaptive, 5.0, &[16, 32, 64]),
    ];
    for (kind, p, steps) in cases {
        let hs: Vec<f64> = steps.iter().map(|n| t_end / *n as f64).collect();
        let errs: Vec<f64> = steps
            .iter()
            .map(|n| (integrate_fixed(kind, &field, *n, t_end) - reference).length())
            .collect();
        let slope = log_slope(&hs, &errs);
        assert!(
            (slope - p).abs() <= 0.3,
            "{kind:?}: order {slope:.3}, expected {p} (errors {errs:?})"
        );
    }
}

#[test]
fn angular_momentum_and_index_invariants() {
    // Spherical field: r x T is conserved; |T| = n along the path.
    let field = TestField::sphere(Profile::FishEye { n0: 2.0, a: 1.0 }, DVec3::ZERO, 20.0, 1.0);
    let o = DVec3::new(0.5, 0.2, 0.0);
    let d = DVec3::new(0.1, 1.0, 0.3).normalize();
    let l0 = o.cross(d * field.sample(o).n);
    let mut s = settings(
        IntegratorKind::Sharma,
        StepSpec::Fixed(0.01),
        ExitMethod::Hermite,
    );
    s.max_steps = 2000;
    let (mut dl, mut dn) = (0.0f64, 0.0f64);
    let res = trace_ray_observed::<f64>(&field, &s, o, d, &mut |seg: &Segment| {
        dl = dl.max((seg.r1.cross(seg.t1) - l0).length());
        dn = dn.max((seg.t1.length() - field.sample(seg.r1).n).abs());
        Control::Continue
    });
    assert_eq!(res.status, RayStatus::MaxSteps);
    assert_eq!(res.steps, 2000);
    assert!(dl <= 1e-9 * l0.length(), "r x T drift {dl:e}");
    assert!(dn <= 1e-9, "|T| - n drift {dn:e}");

    // Stratified field: the horizontal components of T are conserved by every integrator.
    let strat = TestField::cuboid(
        Profile::Stratified { e: 0.05, h: 0.3 },
        DVec3::new(-5.0, 0.0, -5.0),
        DVec3::new(5.0, 2.0, 5.0),
        1.0,
    );
    let o = DVec3::new(-4.0, 0.5, 0.0);
    let d = DVec3::new(1.0, -0.02, 0.3).normalize();
    let th0 = d * strat.sample(o).n;
    for kind in IntegratorKind::ALL {
        let s = settings(kind, StepSpec::Fixed(0.02), ExitMethod::Hermite);
        let mut worst = 0.0f64;
        trace_ray_observed::<f64>(&strat, &s, o, d, &mut |seg: &Segment| {
            worst = worst
                .max((seg.t1.x - th0.x).abs())
                .max((seg.t1.z - th0.z).abs());
            Control::Continue
        });
        assert!(worst <= 1e-13, "{kind:?}: horizontal T drift {worst:e}");
    }
}

/// Max over steps of ||T| - n| on a closed Luneburg orbit (r'' = -r), with fixed h in t,
/// sampled over the first `early` steps and over all `steps`.
fn orbit_drift(kind: IntegratorKind, steps: u32, early: u32) -> (f64, f64) {
    let field = TestField::sphere(
        Profile::Luneburg {
            c: DVec3::ZERO,
            radius: 1.0,
        },
        DVec3::ZERO,
        1.0,
        1.0,
    );
    let r0 = DVec3::new(0.5, 0.0, 0.0);
    let mut s = RayState::<f64> {
        r: r0,
        t: DVec3::new(0.0, 0.8, 0.6) * field.sample(r0).n,
    };
    let h = 0.01;
    let (mut first, mut all) = (0.0f64, 0.0f64);
    for i in 0..steps {
        let d0 = field.sample(s.r).n_grad_n();
        s = integrate::step(kind, &field, s, d0, h).state;
        let dev = (s.t.length() - field.sample(s.r).n).abs();
        if !dev.is_finite() {
            return (first, f64::INFINITY);
        }
        all = all.max(dev);
        if i < early {
            first = first.max(dev);
        }
    }
    (first, all)
}

#[test]
fn symplectic_methods_stay_bounded_while_euler_drifts() {
    const STEPS: u32 = 100_000;
    const EARLY: u32 = 1_000;
    for kind in [IntegratorKind::SymplecticEuler, IntegratorKind::Verlet] {
        let (first, all) = orbit_drift(kind, STEPS, EARLY);
        // Bounded: one orbit (~630 steps) shows the whole oscillation; 1e5 steps add nothing.
        assert!(
            all <= 2.0 * first + 1e-12,
            "{kind:?}: |T| - n grew from {first:e} to {all:e}"
        );
        assert!(all <= 1e-2, "{kind:?}: |T| - n = {all:e}");
    }
    let (first, all) = orbit_drift(IntegratorKind::Euler, STEPS, EARLY);
    assert!(
        all > 1.0 && all > 100.0 * first,
        "euler should drift: {first:e} -> {all:e}"
    );
}

/// Textbook Fresnel (unpolarized) from the angles: Rs = sin^2(i - t) / sin^2(i + t),
/// Rp = tan^2(i - t) / tan^2(i + t); normal incidence ((n1 - n2) / (n1 + n2))^2.
fn textbook_reflectance(n1: f64, n2: f64, theta_i: f64) -> f64 {
    if theta_i == 0.0 {
        return ((n1 - n2) / (n1 + n2)).powi(2);
    }
    let theta_t = (n1 / n2 * theta_i.sin()).asin();
    let rs = ((theta_i - theta_t).sin() / (theta_i + theta_t).sin()).powi(2);
    let rp = ((theta_i - theta_t).tan() / (theta_i + theta_t).tan()).powi(2);
    0.5 * (rs + rp)
}

fn ball_case<R: Real>(b: f64, exit: ExitMethod) -> (f64, f64) {
    let n1 = 1.5;
    let field = TestField::sphere(Profile::Uniform { n: n1 }, DVec3::ZERO, 1.0, 1.0);
    let s = settings(IntegratorKind::Sharma, StepSpec::Fixed(0.05), exit);
    let res = trace_ray::<R>(&field, &s, DVec3::new(-3.0, b, 0.0), DVec3::X);
    assert_eq!(res.status, RayStatus::Exited);
    // Two refractions, each deviating by (theta_i - theta_t) towards the axis.
    let ti = b.asin();
    let tt = (b / n1).asin();
    let dev = 2.0 * (ti - tt);
    let expected = DVec3::new(dev.cos(), -dev.sin(), 0.0);
    let r = textbook_reflectance(1.0, n1, ti);
    let expected_tr = (1.0 - r) * (1.0 - r);
    (
        (res.direction - expected).length(),
        (res.transmittance - expected_tr).abs(),
    )
}

#[test]
fn constant_ball_two_refractions_and_fresnel() {
    for exit in [ExitMethod::Hermite, ExitMethod::Bisection] {
        for b in [0.0, 0.2, 0.5, 0.8, 0.95] {
            let (dir_err, tr_err) = ball_case::<f64>(b, exit);
            assert!(
                dir_err <= 1e-10,
                "b = {b}: exit direction off by {dir_err:e}"
            );
            assert!(tr_err <= 1e-11, "b = {b}: transmittance off by {tr_err:e}");
        }
    }
}

fn box_tir_case<R: Real>(exit: ExitMethod) -> RayResult {
    let n1 = 1.5;
    let field = TestField::cuboid(
        Profile::Uniform { n: n1 },
        DVec3::splat(-1.0),
        DVec3::splat(1.0),
        1.0,
    );
    let s = settings(IntegratorKind::Rk4, StepSpec::Fixed(0.05), exit);
    // 60 degrees to the top face's normal (critical angle 41.8 degrees): totally reflected,
    // then meets the x = 1 face at 30 degrees and leaves.
    let d = DVec3::new(60f64.to_radians().sin(), 60f64.to_radians().cos(), 0.0);
    trace_ray::<R>(&field, &s, DVec3::new(-0.9, 0.3, 0.0), d)
}

fn box_tir_expected() -> (DVec3, DVec3, f64) {
    let n1: f64 = 1.5;
    let (s60, c60) = (60f64.to_radians().sin(), 60f64.to_radians().cos());
    // Top face reached at x = -0.9 + 0.7 tan 60; then down to x = 1.
    let x_top = -0.9 + 0.7 * s60 / c60;
    let y_exit = 1.0 - (1.0 - x_top) * c60 / s60;
    let sin_t = n1 * c60;
    let dir = DVec3::new((1.0 - sin_t * sin_t).sqrt(), -sin_t, 0.0);
    let tr = 1.0 - textbook_reflectance(n1, 1.0, 30f64.to_radians());
    (DVec3::new(1.0, y_exit, 0.0), dir, tr)
}

#[test]
fn box_total_internal_reflection_then_refraction() {
    let (p, q, tr) = box_tir_expected();
    for exit in [ExitMethod::Hermite, ExitMethod::Bisection] {
        let res = box_tir_case::<f64>(exit);
        assert_eq!(res.status, RayStatus::Exited, "{exit:?}");
        assert!(
            (res.position - p).length() <= 1e-10,
            "{exit:?}: exit at {} not {p}",
            res.position
        );
        assert!(
            (res.direction - q).length() <= 1e-10,
            "{exit:?}: direction {} not {q}",
            res.direction
        );
        assert!(
            (res.transmittance - tr).abs() <= 1e-12,
            "{exit:?}: transmittance {}",
            res.transmittance
        );
    }
}

#[test]
fn grazing_ray_inside_ball_is_trapped_by_tir() {
    let field = TestField::sphere(Profile::Uniform { n: 1.5 }, DVec3::ZERO, 1.0, 1.0);
    let mut s = settings(
        IntegratorKind::Sharma,
        StepSpec::Fixed(0.05),
        ExitMethod::Hermite,
    );
    s.max_steps = 5000;
    // Impact parameter 0.9 from the centre: incidence asin(0.9) = 64 degrees > critical.
    let o = DVec3::new(0.0, 0.9, 0.0);
    let mut worst = 0.0f64;
    let res = trace_ray_observed::<f64>(&field, &s, o, DVec3::X, &mut |seg: &Segment| {
        worst = worst.max(seg.r1.length() - 1.0);
        Control::Continue
    });
    assert_eq!(res.status, RayStatus::MaxSteps);
    assert_eq!(res.transmittance, 1.0);
    assert!(worst <= 1e-12, "left the ball by {worst:e}");
    // Total reflection keeps the impact parameter: |r x q| = 0.9.
    let b = res.position.cross(res.direction).length();
    assert!((b - 0.9).abs() <= 1e-9, "impact parameter {b}");
}

fn exit_distances<R: Real>(field: &TestField, rays: &[(DVec3, DVec3)]) -> f64 {
    let mut worst = 0.0f64;
    for kind in [
        IntegratorKind::Sharma,
        IntegratorKind::Rk4,
        IntegratorKind::Verlet,
    ] {
        for exit in [ExitMethod::Hermite, ExitMethod::Bisection] {
            let s = settings(kind, StepSpec::Fixed(0.03), exit);
            for (o, d) in rays {
                let res = trace_ray::<R>(field, &s, *o, *d);
                // Left (verlet at 0.03 may say `degraded`: its estimate is above 1e-4 rad).
                assert!(res.status.left(), "{kind:?} {exit:?}: {:?}", res.status);
                worst = worst.max(field.bounds().signed_distance(res.position).abs());
            }
        }
        let s = settings(
            IntegratorKind::Adaptive,
            StepSpec::Adaptive {
                tolerance: 1e-6,
                initial: None,
            },
            ExitMethod::Bisection,
        );
        for (o, d) in rays {
            let res = trace_ray::<R>(field, &s, *o, *d);
            worst = worst.max(field.bounds().signed_distance(res.position).abs());
        }
    }
    worst
}

fn boundary_rays() -> Vec<(DVec3, DVec3)> {
    // From a circle of radius 3 towards points scattered over the inner half of the medium.
    (0..12)
        .map(|i| {
            let a = i as f64 * 0.5;
            let o = DVec3::new(3.0 * a.cos(), 0.7 * a.sin(), 3.0 * a.sin());
            let aim = DVec3::new(0.4 * (2.0 * a).sin(), 0.3 * a.cos(), 0.2 * (3.0 * a).cos());
            (o, aim - o)
        })
        .collect()
}

#[test]
fn exit_points_lie_on_the_surface() {
    let sphere = luneburg();
    let blob_box = TestField::cuboid(
        Profile::Blob {
            c: DVec3::new(0.1, 0.0, -0.2),
            amp: 0.2,
            s: 0.7,
        },
        DVec3::new(-1.0, -0.8, -1.2),
        DVec3::new(1.1, 0.9, 1.0),
        1.0,
    );
    for (name, field) in [("sphere", &sphere), ("box", &blob_box)] {
        let worst = exit_distances::<f64>(field, &boundary_rays());
        assert!(
            worst <= 1e-9 * field.bounds().radius(),
            "{name}: exit {worst:e} from the surface"
        );
    }
}

#[test]
fn f32_path_matches_within_1e_4() {
    let s = settings(
        IntegratorKind::Sharma,
        StepSpec::Fixed((PI / 2.0) / 256.0),
        ExitMethod::Hermite,
    );
    let (worst, _, _) = luneburg_focus::<f32>(&s);
    assert!(worst <= 1e-4, "f32 focus error {worst:e}");
    for exit in [ExitMethod::Hermite, ExitMethod::Bisection] {
        for b in [0.0, 0.5, 0.8] {
            let (dir_err, _) = ball_case::<f32>(b, exit);
            assert!(dir_err <= 1e-4, "f32 ball b = {b}: {dir_err:e}");
        }
        let (p, q, _) = box_tir_expected();
        let res = box_tir_case::<f32>(exit);
        assert!((res.position - p).length() <= 1e-4 && (res.direction - q).length() <= 1e-4);
    }
    // A tolerance below f32 resolution is raised to it instead of shrinking the steps to
    // nothing (step doubling would otherwise stall until max_steps).
    for kind in [
        IntegratorKind::Adaptive,
        IntegratorKind::Sharma,
        IntegratorKind::Rk4,
    ] {
        let mut s = settings(
            kind,
            StepSpec::Adaptive {
                tolerance: 1e-10,
                initial: None,
            },
            ExitMethod::Hermite,
        );
        s.max_steps = 1000;
        let (worst, _, _) = luneburg_focus::<f32>(&s);
        assert!(
            worst <= 1e-4,
            "f32 {kind:?} at tolerance 1e-10: focus error {worst:e}"
        );
    }
    // Linear n^2: the f32 path stays on the parabola and leaves where it should.
    let (n0, k) = (1.2, 0.3);
    let slab = TestField::cuboid(
        Profile::LinearN2 { n0, k },
        DVec3::splat(-1.0),
        DVec3::splat(1.0),
        1.2,
    );
    let o = DVec3::new(-0.9, -0.5, 0.1);
    let d = DVec3::new(1.0, 0.2, 0.05).normalize();
    let t0 = d * slab.sample(o).n;
    let exact = |t: f64| o + t0 * t + DVec3::Y * (0.25 * k * t * t);
    let s = settings(
        IntegratorKind::Sharma,
        StepSpec::Fixed(0.05),
        ExitMethod::Hermite,
    );
    let (mut t_acc, mut worst) = (0.0, 0.0f64);
    let res = trace_ray_observed::<f32>(&slab, &s, o, d, &mut |seg: &Segment| {
        t_acc += seg.h;
        worst = worst.max((seg.r1 - exact(t_acc)).length());
        Control::Continue
    });
    assert!(worst <= 1e-4, "f32 parabola error {worst:e}");
    assert!((res.position - exact((1.0 - o.x) / t0.x)).length() <= 1e-4);
    let worst = exit_distances::<f32>(&luneburg(), &boundary_rays());
    assert!(worst <= 1e-4, "f32 exit {worst:e} from the surface");
    let err = rod_period_error::<f32>(0.02);
    assert!(err <= 1e-4 * 12.0, "f32 rod period error {err:e}");
    // The fish-eye image lies at |P'| = 3.2 a with ~10x magnification. Plain f32 updates
    // r + dr, T + dT lose roundoff linearly over the steps (measured 3.6e-4 at ds 0.01,
    // 4.3e-4 at 0.005); the tracer's compensated summation removes that: 8.7e-5 at
    // ds 0.01, 9.0e-5 at 0.005 (f64: 1.9e-7, 1.2e-8; at ds 0.05 truncation, 1.2e-4,
    // dominates in both precisions).
    let s = settings(
        IntegratorKind::Sharma,
        StepSpec::Fixed(0.01),
        ExitMethod::Hermite,
    );
    let err = fisheye_image_error::<f32>(&s);
    assert!(err <= 1e-4, "f32 fish-eye image error {err:e}");
}

#[test]
fn bad_rays_report_error_and_misses_keep_origin() {
    let field = luneburg();
    let s = settings(
        IntegratorKind::Sharma,
        StepSpec::Fixed(0.01),
        ExitMethod::Hermite,
    );
    let o = DVec3::new(0.0, 0.0, -3.0);
    for d in [
        DVec3::ZERO,
        DVec3::new(f64::NAN, 0.0, 1.0),
        DVec3::new(0.0, f64::INFINITY, 1.0),
    ] {
        assert_eq!(
            trace_ray::<f64>(&field, &s, o, d).status,
            RayStatus::Error,
            "{d}"
        );
    }
    let nan_origin = DVec3::new(0.0, f64::NAN, 0.0);
    assert_eq!(
        trace_ray::<f64>(&field, &s, nan_origin, DVec3::Z).status,
        RayStatus::Error
    );
    let miss = trace_ray::<f64>(
        &field,
        &s,
        DVec3::new(2.0, 0.0, -3.0),
        DVec3::new(0.0, 0.0, 2.0),
    );
    assert_eq!(miss.status, RayStatus::Missed);
    assert_eq!(miss.position, DVec3::new(2.0, 0.0, -3.0));
    assert_eq!(miss.direction, DVec3::Z);
    assert_eq!((miss.steps, miss.evals, miss.opl), (0, 0, 0.0));
}

#[test]
fn macro_cells_fly_straight_through_homogeneous_media() {
    let mut field = TestField::sphere(Profile::Uniform { n: 1.5 }, DVec3::ZERO, 1.0, 1.0);
    let mut s = settings(
        IntegratorKind::Sharma,
        StepSpec::Fixed(0.01),
        ExitMethod::Hermite,
    );
    let o = DVec3::new(-3.0, 0.4, 0.1);
    let stepped = trace_ray::<f64>(&field, &s, o, DVec3::X);
    field.macro_uniform = true;
    s.macro_cells = true;
    let flown = trace_ray::<f64>(&field, &s, o, DVec3::X);
    assert_eq!(flown.status, RayStatus::Exited);
    assert_eq!(flown.steps, 1);
    assert!(
        flown.evals < 5 && stepped.evals > 100,
        "{} vs {}",
        flown.evals,
        stepped.evals
    );
    assert!((flown.direction - stepped.direction).length() <= 1e-12);
    assert!((flown.position - stepped.position).length() <= 1e-12);
    assert!(
        (flown.opl - stepped.opl).abs() <= 1e-12 && (flown.length - stepped.length).abs() <= 1e-12
    );
}

/// Hermite exit (root of the dense output, one re-step, projection) against the paper's
/// bisection on the step length: focus error and field evaluations over the Luneburg beam
/// at coarse to fine steps. Hermite must be as accurate (within 2x, or both at roundoff)
/// for a fraction of the evaluations spent finding the exit.
#[test]
fn hermite_exit_is_as_accurate_and_cheaper_than_bisection() {
    for per_quarter in [16.0, 64.0, 256.0] {
        let ds = (PI / 2.0) / per_quarter;
        let mut measured = Vec::new();
        for exit in [ExitMethod::Hermite, ExitMethod::Bisection] {
            let s = settings(IntegratorKind::Sharma, StepSpec::Fixed(ds), exit);
            let field = luneburg();
            let (mut worst, mut evals) = (0.0f64, 0u64);
            for o in beam() {
                let res = trace_ray::<f64>(&field, &s, o, DVec3::Z);
                worst = worst.max((res.position - DVec3::Z).length());
                evals += res.evals;
            }
            eprintln!(
                "steps/quarter {per_quarter}: {exit:?} focus error {worst:.2e}, evals {evals}"
            );
            measured.push((worst, evals));
        }
        let ((e_h, n_h), (e_b, n_b)) = (measured[0], measured[1]);
        assert!(
            e_h <= 2.0 * e_b || e_h <= 1e-12,
            "hermite {e_h:e} vs bisection {e_b:e}"
        );
        assert!(n_h < n_b, "hermite {n_h} evals vs bisection {n_b}");
    }
}

#[test]
fn air_bubble_in_glass_reflects_grazing_rays_on_entry() {
    // n = 1 inside, 1.5 outside: beyond the critical angle asin(1/1.5) the ray never enters.
    let field = TestField::sphere(Profile::Uniform { n: 1.0 }, DVec3::ZERO, 1.0, 1.5);
    let s = settings(
        IntegratorKind::Sharma,
        StepSpec::Fixed(0.05),
        ExitMethod::Hermite,
    );
    let b: f64 = 0.9;
    let res = trace_ray::<f64>(&field, &s, DVec3::new(-3.0, b, 0.0), DVec3::X);
    assert_eq!(res.status, RayStatus::Exited);
    let hit = DVec3::new(-(1.0 - b * b).sqrt(), b, 0.0);
    assert!((res.position - hit).length() <= 1e-12);
    let mirrored = DVec3::X - hit * (2.0 * DVec3::X.dot(hit));
    assert!(
        (res.direction - mirrored).length() <= 1e-12,
        "{}",
        res.direction
    );
    assert_eq!((res.steps, res.length), (0, 0.0));
    // Below the critical angle it crosses, diverging: deviation 2 (theta_t - theta_i) away.
    let b: f64 = 0.5;
    let res = trace_ray::<f64>(&field, &s, DVec3::new(-3.0, b, 0.0), DVec3::X);
    let (ti, tt) = (b.asin(), (1.5 * b).asin());
    let dev = 2.0 * (tt - ti);
    assert!((res.direction - DVec3::new(dev.cos(), dev.sin(), 0.0)).length() <= 1e-10);
    let r = textbook_reflectance(1.5, 1.0, ti);
    assert!((res.transmittance - (1.0 - r) * (1.0 - r)).abs() <= 1e-11);
}

/// Fermat on the Luneburg lens: every ray of a parallel beam has the same optical path
/// from the plane z = -2 to the focus (0, 0, 1), 2 + pi/2. dopri's optical path is summed
/// with its own fifth-order weights, and with a table's control (`opl_control`) its
/// embedded error is held to the tolerance as the position's is: at each tolerance the
/// path is within it and within 4x the exit position's error (measured: 6.2e-7 against
/// 2.2e-7 at 1e-6, 4.4e-10 against 2.4e-10 at 1e-9; the lens pulls the exits' errors back
/// to its focus, the path sums every step's). Without the control the path's error is
/// 2.0e-6 at 1e-6, over the tolerance and over twice the controlled one (the cubic
/// Hermite rule had it 46x the exit's).
#[test]
fn optical_path_is_as_accurate_as_the_exit_position() {
    let field = luneburg();
    let focus = DVec3::new(0.0, 0.0, 1.0);
    let worst = |tol: f64, opl_control: bool| {
        let s = TraceSettings {
            opl_control,
            ..settings(
                IntegratorKind::Adaptive,
                StepSpec::Adaptive {
                    tolerance: tol,
                    initial: None,
                },
                ExitMethod::Hermite,
            )
        };
        let (mut worst_pos, mut worst_opl) = (0.0f64, 0.0f64);
        for o in beam() {
            let r = trace_ray::<f64>(&field, &s, o, DVec3::Z);
            assert_eq!(r.status, RayStatus::Exited, "{o}");
            let rho2 = o.x * o.x + o.y * o.y;
            let total = (2.0 - (1.0 - rho2).sqrt()) + r.opl;
            worst_opl = worst_opl.max((total - (2.0 + PI / 2.0)).abs());
            worst_pos = worst_pos.max((r.position - focus).length());
        }
        (worst_pos, worst_opl)
    };
    for tol in [1e-6, 1e-9] {
        let (pos, opl) = worst(tol, true);
        eprintln!("tol {tol}: optical path {opl:.2e}, exit position {pos:.2e}");
        assert!(
            opl <= tol && pos <= tol && opl <= 4.0 * pos,
            "tol {tol}: optical path off by {opl:e}, exit position by {pos:e}"
        );
    }
    let (_, controlled) = worst(1e-6, true);
    let (_, uncontrolled) = worst(1e-6, false);
    assert!(
        controlled < 0.5 * uncontrolled,
        "the control holds the path: {controlled:e} against {uncontrolled:e} without"
    );
}

/// A ray that flies straight over a uniform medium's macro cells to a face where it
/// reflects totally goes on from that face (it used to start the same flight again
/// from where the first began, until `max_steps`). Uniform n = 1.5 in a box, entered
/// through its -z face at 70 degrees: inside at asin(sin 70 / 1.5) = 38.8 degrees, it
/// meets the +x face at 51.2 degrees (past the critical 41.8), reflects, and leaves
/// through the +z face as it came in, mirrored in x: the exact straight-line answer.
#[test]
fn a_flight_that_reflects_totally_goes_on_from_the_surface() {
    let bounds = grin_field::Bounds::Box {
        min: DVec3::splat(-1.0),
        max: DVec3::splat(1.0),
    };
    let uniform = grin_field::expr::ExprField::new("1.5", bounds, 1.0, 0.0).expect("uniform");
    let opts = grin_field::bake::BakeOptions {
        resolution: Some(8),
        crop: false,
        error_points: 100,
        ..Default::default()
    };
    let (baked, _) =
        grin_field::bake::bake(&uniform, &opts, &|_: &str, _: u64, _: u64| {}).expect("bake");
    let (sin_i, cos_i) = 70f64.to_radians().sin_cos();
    let entry = DVec3::new(0.5, 0.0, -1.0);
    let d = DVec3::new(sin_i, 0.0, cos_i);
    // Inside: the refracted direction, to the +x face, mirrored, to the +z face.
    let sin_t = sin_i / 1.5;
    let inside = DVec3::new(sin_t, 0.0, (1.0 - sin_t * sin_t).sqrt());
    let at_x = entry + inside * ((1.0 - entry.x) / inside.x);
    let back = DVec3::new(-inside.x, 0.0, inside.z);
    let at_z = at_x + back * ((1.0 - at_x.z) / back.z);
    let want_dir = DVec3::new(-sin_i, 0.0, cos_i);
    let s = TraceSettings {
        macro_cells: true,
        ..settings(
            IntegratorKind::Rk4,
            StepSpec::Fixed(0.05),
            ExitMethod::Hermite,
        )
    };
    let mut flights = 0;
    let mut count = |seg: &Segment| {
        // A flight's segment is a straight chord longer than the step.
        if (seg.r1 - seg.r0).length() > 0.1 {
            flights += 1;
        }
        Control::Continue
    };
    let r = trace_ray_observed::<f64>(&baked, &s, entry - d * 2.0, d, &mut count);
    assert!(r.status.left(), "{:?} after {} steps", r.status, r.steps);
    assert!(flights >= 2, "{flights} flights: the medium is flown over");
    assert!(
        (r.position - at_z).length() < 1e-9,
        "left at {} (exact {at_z})",
        r.position
    );
    // The bake holds n to its storage's precision (the direction out follows n there).
    assert!(
        (r.direction - want_dir).length() < 1e-6,
        "direction {} (exact {want_dir})",
        r.direction
    );
}

/// A ray from far away enters where it meets the surface: the entry point is put on the
/// surface, so the rounding of `origin + d s_in` (1e-10 from 1e6 away, more than the
/// entry nudge's few ulps of the medium) does not leave the ray outside, where it used to
/// "exit" at its entry point unbent (`exited`, opl ~1e-32). The Luneburg lens focuses a
/// ray from 1e7 away as one from 2 away; a box 2e-6 thin is crossed whole from 3 away.
#[test]
fn a_ray_from_far_away_enters_the_medium() {
    let field = luneburg();
    let s = settings(
        IntegratorKind::Adaptive,
        StepSpec::Adaptive {
            tolerance: 1e-10,
            initial: None,
        },
        ExitMethod::Hermite,
    );
    let focus = DVec3::new(0.0, 0.0, 1.0);
    for z in [-2.0, -1e5, -3e5, -1e6, -5e6, -1e7] {
        for o in [DVec3::new(0.3, 0.0, z), DVec3::new(0.0, 0.5, z)] {
            let r = trace_ray::<f64>(&field, &s, o, DVec3::Z);
            assert_eq!(r.status, RayStatus::Exited, "{o}");
            // The origin's own rounding at 1e7 (1.9e-9) moves the ray by as much.
            assert!(
                (r.position - focus).length() < 1e-8,
                "{o}: exit {}",
                r.position
            );
            let rho2 = o.x * o.x + o.y * o.y;
            let total = (1.0 - (1.0 - rho2).sqrt()) + r.opl;
            assert!(
                (total - (1.0 + PI / 2.0)).abs() < 1e-8,
                "{o}: opl {}",
                r.opl
            );
        }
    }
    let thin = grin_field::expr::ExprField::new(
        "1.5",
        grin_field::Bounds::Box {
            min: DVec3::new(-1.0, -1.0, -1e-6),
            max: DVec3::new(1.0, 1.0, 1e-6),
        },
        1.0,
        0.0,
    )
    .expect("thin slab");
    for z in [-0.1, -3.0, -1e4] {
        let r = trace_ray::<f64>(&thin, &s, DVec3::new(0.2, 0.1, z), DVec3::Z);
        assert_eq!(r.status, RayStatus::Exited);
        assert_eq!(r.position.z, 1e-6, "from {z}: exit {}", r.position);
        assert!((r.opl - 3e-6).abs() < 1e-15, "from {z}: opl {}", r.opl);
    }
}
