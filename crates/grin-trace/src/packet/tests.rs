//! The packets against the one-ray tracer: bit for bit, case by case.

use grin_field::analytic::{Luneburg, Plume};
use grin_field::expr::ExprField;
use grin_scene::{ExitMethod, PlumeBlob};

use super::*;
use crate::table::result_values;
use crate::trace::trace_ray;

fn settings(ds: f64, max_steps: u32, exit: ExitMethod) -> TraceSettings {
    TraceSettings {
        integrator: IntegratorKind::Rk4,
        step: StepSpec::Fixed(ds),
        max_steps,
        exit,
        macro_cells: true,
        accuracy: grin_scene::DEFAULT_AUTO_ACCURACY,
        estimate_limit: grin_scene::DEFAULT_AUTO_ACCURACY,
        opl_control: false,
    }
}

/// dopri 5(4) under error control: per step (`adaptive`) or per length (`auto`).
fn dopri(step: StepSpec, max_steps: u32) -> TraceSettings {
    TraceSettings {
        integrator: IntegratorKind::Adaptive,
        step,
        ..settings(0.0, max_steps, ExitMethod::Hermite)
    }
}

/// Rays from all around: most cross the medium, some miss it, some graze it.
fn rays(center: DVec3, spread: f64, count: usize) -> Vec<(DVec3, DVec3)> {
    let mut seed = 0x1234_5678_9abc_def1_u64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    (0..count)
        .map(|_| {
            let o = center + DVec3::new(next(), next(), -3.0) * spread;
            let d = DVec3::new(next() * 0.3, next() * 0.3, 1.0);
            (o, d)
        })
        .collect()
}

/// A table traced in packets (with the CPU's widest lane vectors and with the
/// target's own) is the table traced ray by ray, bit for bit, on a box
/// and a sphere, with the field's step caps, rays that miss and graze, the bisection
/// exit and a step cap that ends rays at `max_steps`.
#[test]
fn packets_are_the_scalar_tracer_bit_for_bit() {
    let rod = ExprField::benchmark_rod();
    let ball = Bounds::Sphere {
        center: DVec3::ZERO,
        radius: 1.0,
    };
    let lens = Luneburg::new(ball, 1.0, None).expect("lens");
    let plume = Plume::new(
        Bounds::Box {
            min: DVec3::splat(-1.0),
            max: DVec3::splat(1.0),
        },
        1.0,
        &[PlumeBlob {
            a: -1e-3,
            center: [0.1, 0.0, 0.2],
            s: 0.05,
        }],
    )
    .expect("plume");
    // The plume baked whole (no crop): ambient macro cells all around the blob, flown
    // over straight, and f32 samples (the error control's floor is theirs).
    let opts = grin_field::bake::BakeOptions {
        resolution: Some(24),
        crop: false,
        error_points: 100,
        ..Default::default()
    };
    let (baked, _) =
        grin_field::bake::bake(&plume, &opts, &|_: &str, _: u64, _: u64| {}).expect("bake");
    assert!(baked.sample_eps() > f64::EPSILON);
    let bump = ExprField::new(
        "1.2 + 0.1*exp(-((x - 0.3)^2 + y^2 + z^2)/0.001)",
        ball,
        1.0,
        0.0,
    )
    .expect("bump");
    // A strong gradient across the sphere: rays that reach its surface in the dense
    // part at a slant reflect totally (an exit search that ends inside again).
    let slab = ExprField::new("1.5 + 0.45*y", ball, 1.0, 0.0).expect("slab");
    // The packets skip asking the rod for local caps, not the bump.
    assert!(!rod.has_local_step_limits() && bump.has_local_step_limits());
    let adaptive = |tolerance| StepSpec::Adaptive {
        tolerance,
        initial: None,
    };
    let cases: [(&dyn IndexField, DVec3, f64, TraceSettings); 20] = [
        (
            &rod,
            DVec3::new(0.0, 0.0, 1.0),
            1.0,
            settings(0.1, 1_000_000, ExitMethod::Hermite),
        ),
        (
            &rod,
            DVec3::new(0.0, 0.0, 1.0),
            1.0,
            settings(0.37, 1_000_000, ExitMethod::Bisection),
        ),
        (
            &lens,
            DVec3::ZERO,
            0.5,
            settings(0.05, 1_000_000, ExitMethod::Hermite),
        ),
        (
            &lens,
            DVec3::ZERO,
            0.5,
            settings(0.05, 17, ExitMethod::Hermite),
        ),
        (
            &plume,
            DVec3::ZERO,
            0.5,
            settings(0.02, 1_000_000, ExitMethod::Hermite),
        ),
        (
            &bump,
            DVec3::ZERO,
            0.4,
            settings(0.04, 1_000_000, ExitMethod::Hermite),
        ),
        (
            &rod,
            DVec3::new(0.0, 0.0, 1.0),
            1.0,
            dopri(adaptive(1e-9), 1_000_000),
        ),
        (
            &lens,
            DVec3::ZERO,
            0.5,
            dopri(StepSpec::Auto(1e-7), 1_000_000),
        ),
        (&lens, DVec3::ZERO, 0.5, dopri(adaptive(1e-6), 9)),
        (
            &plume,
            DVec3::ZERO,
            0.5,
            dopri(StepSpec::Auto(1e-6), 1_000_000),
        ),
        (&bump, DVec3::ZERO, 0.4, dopri(adaptive(1e-8), 1_000_000)),
        (
            &lens,
            DVec3::ZERO,
            0.5,
            dopri(StepSpec::Fixed(0.04), 1_000_000),
        ),
        (
            &bump,
            DVec3::ZERO,
            0.4,
            dopri(StepSpec::Fixed(0.03), 1_000_000),
        ),
        (
            &baked,
            DVec3::ZERO,
            0.5,
            settings(0.05, 1_000_000, ExitMethod::Hermite),
        ),
        (
            &baked,
            DVec3::ZERO,
            0.5,
            dopri(StepSpec::Auto(1e-6), 1_000_000),
        ),
        (
            &lens,
            DVec3::ZERO,
            0.5,
            TraceSettings {
                exit: ExitMethod::Bisection,
                ..dopri(adaptive(1e-7), 1_000_000)
            },
        ),
        (
            &slab,
            DVec3::ZERO,
            0.6,
            settings(0.03, 1_000_000, ExitMethod::Hermite),
        ),
        (&slab, DVec3::ZERO, 0.6, dopri(adaptive(1e-8), 1_000_000)),
        // The optical path's error under control too (ray tables).
        (
            &lens,
            DVec3::ZERO,
            0.5,
            TraceSettings {
                opl_control: true,
                ..dopri(adaptive(1e-6), 1_000_000)
            },
        ),
        (
            &rod,
            DVec3::new(0.0, 0.0, 1.0),
            1.0,
            TraceSettings {
                opl_control: true,
                ..dopri(StepSpec::Auto(1e-7), 1_000_000)
            },
        ),
    ];
    // The cases on the slab, and the rays there that reflect totally at least once.
    const REFLECTING: [usize; 2] = [16, 17];
    let reflections = |field: &dyn IndexField, s: &TraceSettings, o: DVec3, d: DVec3| {
        let mut on_surface = 0;
        let mut count = |seg: &Segment| {
            if field.bounds().signed_distance(seg.r1).abs() < 1e-9 {
                on_surface += 1;
            }
            Control::Continue
        };
        crate::trace::trace_ray_observed::<f64>(field, s, o, d, &mut count);
        on_surface - 1
    };
    // The cases on the baked plume.
    const FLIGHTS: [usize; 2] = [13, 14];
    for (k, (field, center, spread, s)) in cases.iter().enumerate() {
        let table = rays(*center, *spread, 301);
        if s.opl_control {
            // The path's error shortens some of these rays' steps.
            let without = TraceSettings {
                opl_control: false,
                ..*s
            };
            let shortened = table
                .iter()
                .filter(|&&(o, d)| {
                    trace_ray::<f64>(*field, s, o, d).evals
                        != trace_ray::<f64>(*field, &without, o, d).evals
                })
                .count();
            eprintln!("case {k}: the path's error changes {shortened} rays' steps");
            assert!(shortened > 0, "case {k}: the path's error changes no step");
        }
        // The widest lane vectors the CPU has, and the target's own.
        for portable in [false, true] {
            let mut packed = vec![untraced_result(); table.len()];
            let counts =
                trace_packets_with(*field, s, &table, &mut packed, packet_step(s, portable));
            let mut steps = 0;
            for (i, &(o, d)) in table.iter().enumerate() {
                let want = trace_ray::<f64>(*field, s, o, d);
                let got = packed[i];
                steps += u64::from(got.steps);
                assert_eq!(got.status, want.status, "case {k} ray {i} ({portable})");
                let bits = |r: &RayResult| {
                    let [px, py, pz, dx, dy, dz, opl, length] = result_values(r);
                    let (s, t) = (r.swept, r.transmittance);
                    let (e, c) = (r.error_estimate, r.crossing_uncertainty);
                    [px, py, pz, dx, dy, dz, opl, length, s.x, s.y, s.z, t, e, c].map(f64::to_bits)
                };
                assert_eq!(
                    bits(&got),
                    bits(&want),
                    "case {k} ray {i}: {got:?} vs {want:?}"
                );
                assert_eq!(
                    (got.steps, got.evals),
                    (want.steps, want.evals),
                    "case {k} ray {i}"
                );
            }
            let in_packets = counts.steps;
            let exited = packed.iter().filter(|r| r.status.left()).count();
            eprintln!(
                "case {k}: {in_packets} of {steps} steps in packets, {} of {exited} exits",
                counts.exits
            );
            let own = steps - in_packets;
            // The exits the packets searched, each recorded by its march: one per ray
            // that left, and one per total reflection (Hermite's; bisection's are the
            // march's own).
            let hermite = s.exit == ExitMethod::Hermite;
            if REFLECTING.contains(&k) {
                let reflecting = table
                    .iter()
                    .filter(|&&(o, d)| reflections(*field, s, o, d) > 0)
                    .count();
                eprintln!("case {k}: {reflecting} rays reflect totally");
                assert!(reflecting >= 10, "case {k}: {reflecting} rays reflect");
                assert!(counts.exits >= (exited + reflecting) as u64, "case {k}");
            }
            if FLIGHTS.contains(&k) {
                // The baked plume's rays fly over its ambient macro cells, in
                // their marches.
                assert!(own > table.len() as u64, "case {k}: {own} march steps");
            } else {
                // Elsewhere the march's own steps are the ones that leave (bisection's),
                // or none but the records of the exits the packets found (Hermite's):
                // the steps near the surface that stay inside are the packets'.
                let (searched, leaving) = if hermite {
                    (counts.exits, 0)
                } else {
                    (0, table.len() as u64)
                };
                assert!(
                    own - searched <= leaving,
                    "case {k}: {in_packets} of {steps} steps in packets, {searched} exits"
                );
                if hermite && !REFLECTING.contains(&k) {
                    assert_eq!(counts.exits, exited as u64, "case {k}: exits in packets");
                }
            }
        }
    }
}

/// `trace_rows_into` leaves in a vector that held a longer batch, and then a shorter one,
/// what a fresh trace gives, in packets (f64 rk4) and ray by ray (f32): no slot keeps a
/// result of the batch before.
#[test]
fn traced_rows_fill_a_reused_vector_as_a_fresh_one() {
    use crate::table::{RayRow, trace_rows, trace_rows_into};
    let ball = Bounds::Sphere {
        center: DVec3::ZERO,
        radius: 1.0,
    };
    let lens = Luneburg::new(ball, 1.0, None).expect("lens");
    let row = |(k, &(origin, dir)): (usize, &(DVec3, DVec3))| RayRow {
        line: k + 2,
        origin,
        dir,
        extra: Vec::new(),
    };
    let batch = |center: DVec3, count: usize| -> Vec<RayRow> {
        rays(center, 0.6, count)
            .iter()
            .enumerate()
            .map(row)
            .collect()
    };
    // A long batch, then a shorter one over other rays, then a longer one again.
    let batches = [
        batch(DVec3::ZERO, 700),
        batch(DVec3::new(0.3, -0.2, 0.0), 150),
        batch(DVec3::new(-0.4, 0.1, 0.0), 400),
    ];
    let s = settings(0.05, 100_000, ExitMethod::Hermite);
    let bits = |r: &RayResult| result_values(r).map(f64::to_bits);
    let mut packed = Vec::new();
    let mut single = Vec::new();
    for rows in &batches {
        trace_rows_into::<f64>(&lens, &s, rows, &mut packed);
        trace_rows_into::<f32>(&lens, &s, rows, &mut single);
        let fresh = (
            trace_rows::<f64>(&lens, &s, rows),
            trace_rows::<f32>(&lens, &s, rows),
        );
        assert_eq!(packed.len(), rows.len());
        assert_eq!(single.len(), rows.len());
        for (got, want) in [(&packed, &fresh.0), (&single, &fresh.1)] {
            for (i, (g, w)) in got.iter().zip(want).enumerate() {
                assert_eq!(g.status, w.status, "ray {i}");
                assert_eq!(bits(g), bits(w), "ray {i}");
            }
        }
    }
}
