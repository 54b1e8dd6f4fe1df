//! The tracer on grin-field's own analytic profiles (built from scene specs by
//! `build_field`, as `grin trace` does), against those profiles' exact ray solutions.

mod common;

use std::f64::consts::PI;
use std::path::Path;
use std::sync::Arc;

use common::golden_min;
use glam::DVec3;
use grin_field::IndexField;
use grin_field::analytic::{grin_rod, linear_n2, luneburg, maxwell_fish_eye};
use grin_render::settings::TraceSettings;
use grin_scene::{Axis, BoundsSpec, ExitMethod, FieldSpec, IntegratorKind, MediumSpec, StepSpec};
use grin_trace::{Control, RayStatus, Segment, trace_ray, trace_ray_observed};

fn build(field: FieldSpec, bounds: BoundsSpec, ambient_index: f64) -> Arc<dyn IndexField> {
    let medium = MediumSpec {
        bounds,
        ambient_index: ambient_index.into(),
        field,
    };
    match grin_field::build_field(&medium, Path::new(".")) {
        Ok(f) => f,
        Err(e) => panic!("{e}"),
    }
}

fn settings(integrator: IntegratorKind, step: StepSpec) -> TraceSettings {
    TraceSettings {
        integrator,
        step,
        max_steps: 1_000_000,
        exit: ExitMethod::Hermite,
        macro_cells: true,
        accuracy: grin_scene::DEFAULT_AUTO_ACCURACY,
        estimate_limit: grin_scene::DEFAULT_AUTO_ACCURACY,
    }
}

/// Follow a ray from inside and compare every step end with `exact(r0, T0, t)`.
fn path_error(
    field: &dyn IndexField,
    s: &TraceSettings,
    o: DVec3,
    d: DVec3,
    exact: impl Fn(DVec3, DVec3, f64) -> (DVec3, DVec3),
) -> f64 {
    let t0 = d.normalize() * field.sample(o).n;
    let mut t = 0.0;
    let mut worst = 0.0f64;
    let res = trace_ray_observed::<f64>(field, s, o, d, &mut |seg: &Segment| {
        t += seg.h;
        let (r, _) = exact(o, t0, t);
        worst = worst.max((seg.r1 - r).length());
        Control::Continue
    });
    assert_eq!(res.status, RayStatus::Exited);
    worst
}

#[test]
fn luneburg_profile_exact_ellipses_and_focus() {
    let c = DVec3::new(0.2, -0.1, 0.3);
    let field = build(
        FieldSpec::Luneburg { radius: None },
        BoundsSpec::Sphere {
            center: c.to_array(),
            radius: 2.0,
        },
        1.0,
    );
    let s = settings(IntegratorKind::Sharma, StepSpec::Fixed(0.005));
    let o = c + DVec3::new(0.3, 0.5, -0.2);
    let err = path_error(
        field.as_ref(),
        &s,
        o,
        DVec3::new(0.2, 0.1, 1.0),
        |r0, t0, t| luneburg::exact_path(r0 - c, t0, 2.0, t).map_first(|r| r + c),
    );
    assert!(err <= 1e-9, "Luneburg path error {err:e}");
    let s = settings(
        IntegratorKind::Adaptive,
        StepSpec::Adaptive {
            tolerance: 1e-10,
            initial: None,
        },
    );
    for (x, y) in [(0.0, 0.0), (1.2, -0.7), (-1.5, 0.9), (0.3, 1.85)] {
        let res = trace_ray::<f64>(field.as_ref(), &s, c + DVec3::new(x, y, -5.0), DVec3::Z);
        let err = (res.position - (c + DVec3::Z * 2.0)).length();
        assert!(
            err <= 1e-7 * 2.0,
            "focus error {err:e} for ray at ({x}, {y})"
        );
    }
}

trait MapFirst {
    fn map_first(self, f: impl Fn(DVec3) -> DVec3) -> (DVec3, DVec3);
}

impl MapFirst for (DVec3, DVec3) {
    fn map_first(self, f: impl Fn(DVec3) -> DVec3) -> (DVec3, DVec3) {
        (f(self.0), self.1)
    }
}

#[test]
fn grin_rod_profile_helix_and_period() {
    let (n0, a) = (1.6, 0.4);
    let field = build(
        FieldSpec::GrinRod {
            n0,
            a,
            axis: Axis::Z,
        },
        BoundsSpec::Box {
            min: [-1.0, -1.0, 0.0],
            max: [1.0, 1.0, 30.0],
        },
        1.0,
    );
    let s = settings(IntegratorKind::Rk4, StepSpec::Fixed(0.004));
    let c = DVec3::new(0.0, 0.0, 15.0);
    let o = DVec3::new(0.2, -0.3, 0.5);
    let d = DVec3::new(0.15, 0.05, 1.0);
    let err = path_error(field.as_ref(), &s, o, d, |r0, t0, t| {
        let (r, tt) = grin_rod::exact_path(r0 - c, t0, n0, a, DVec3::Z, t);
        (r + c, tt)
    });
    assert!(err <= 1e-9, "rod helix error {err:e}");
    let beta = field.sample(o).n * d.normalize().z;
    let period = grin_rod::z_period(n0, a, beta);
    assert!((period - 2.0 * PI * beta / (n0 * a)).abs() <= 1e-12);
}

#[test]
fn linear_n2_profile_parabola() {
    let (n0, k) = (1.3, 0.4);
    let field = build(
        FieldSpec::LinearN2 {
            n0,
            k,
            axis: Axis::Y,
        },
        BoundsSpec::Box {
            min: [-1.0; 3],
            max: [1.0; 3],
        },
        1.0,
    );
    for kind in [IntegratorKind::Sharma, IntegratorKind::Rk4] {
        let s = settings(kind, StepSpec::Fixed(0.1));
        let err = path_error(
            field.as_ref(),
            &s,
            DVec3::new(-0.8, 0.2, 0.0),
            DVec3::new(1.0, -0.3, 0.2),
            |r0, t0, t| linear_n2::exact_path(r0, t0, k, DVec3::Y, t),
        );
        assert!(err <= 1e-12, "{kind:?}: parabola error {err:e}");
    }
}

#[test]
fn fish_eye_profile_images_point() {
    let (n0, a) = (1.8, 1.0);
    let field = build(
        FieldSpec::MaxwellFishEye { n0, a },
        BoundsSpec::Sphere {
            center: [0.0; 3],
            radius: 15.0,
        },
        1.0,
    );
    let p = DVec3::new(-0.2, 0.35, 0.1);
    let image = maxwell_fish_eye::image_point(p, a);
    let s = settings(IntegratorKind::Sharma, StepSpec::Fixed(1e-3));
    for d in [
        DVec3::new(0.3, 0.2, 1.0),
        DVec3::new(-0.5, 0.1, -1.0),
        DVec3::new(0.0, 1.0, 0.4),
    ] {
        let mut best = f64::INFINITY;
        let mut was_near = false;
        let res = trace_ray_observed::<f64>(field.as_ref(), &s, p, d, &mut |seg: &Segment| {
            if (seg.r0 - image).length().min((seg.r1 - image).length()) < 0.1 {
                was_near = true;
                best = best.min(golden_min(0.0, seg.h, |tau| (seg.point(tau) - image).length()).1);
                Control::Continue
            } else if was_near {
                Control::Stop
            } else {
                Control::Continue
            }
        });
        assert_eq!(res.status, RayStatus::Absorbed);
        assert!(best <= 1e-7 * a, "fish-eye image miss {best:e} for {d}");
    }
}
