//! ns per ray of the CPU tracer: a Luneburg beam and a hot-air plume, for each integrator
//! and step policy, in f64 and f32. Run: `cargo bench -p grin-trace --bench trace`.

use std::path::Path;
use std::sync::Arc;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::DVec3;
use grin_field::{IndexField, Real};
use grin_render::settings::TraceSettings;
use grin_scene::{
    BoundsSpec, ExitMethod, FieldSpec, IntegratorKind, MediumSpec, PlumeBlob, StepSpec,
};
use grin_trace::trace_ray;

/// Rays per beam: one benchmark iteration traces them all.
const BEAM: usize = 64;

fn field(spec: FieldSpec, bounds: BoundsSpec) -> Arc<dyn IndexField> {
    let medium = MediumSpec {
        bounds,
        ambient_index: 1.0.into(),
        field: spec,
    };
    match grin_field::build_field(&medium, Path::new(".")) {
        Ok(f) => f,
        Err(e) => panic!("bench field: {e}"),
    }
}

/// A parallel beam along +z through the unit disk (golden-angle spiral).
fn beam() -> Vec<(DVec3, DVec3)> {
    (0..BEAM)
        .map(|i| {
            let r = 0.95 * ((i as f64 + 0.5) / BEAM as f64).sqrt();
            let a = i as f64 * 2.399_963_229_728_653;
            (DVec3::new(r * a.cos(), r * a.sin(), -3.0), DVec3::Z)
        })
        .collect()
}

fn configs() -> Vec<(&'static str, IntegratorKind, StepSpec)> {
    let fixed = StepSpec::Fixed(0.01);
    let mut out: Vec<(&'static str, IntegratorKind, StepSpec)> = IntegratorKind::ALL
        .iter()
        .map(|k| ("fixed=0.01", *k, fixed))
        .collect();
    let heuristic = StepSpec::Heuristic {
        min: 0.002,
        max: 0.02,
        amplitude: None,
    };
    let adaptive = StepSpec::Adaptive {
        tolerance: 1e-8,
        initial: None,
    };
    out.push(("heuristic=0.002,0.02", IntegratorKind::Sharma, heuristic));
    out.push(("adaptive=1e-8", IntegratorKind::Sharma, adaptive));
    out.push(("adaptive=1e-8", IntegratorKind::Adaptive, adaptive));
    out
}

fn bench_field<R: Real>(c: &mut Criterion, name: &str, f: &dyn IndexField, precision: &str) {
    let rays = beam();
    let mut group = c.benchmark_group(format!("trace/{name}/{precision}"));
    group.throughput(Throughput::Elements(BEAM as u64));
    for (policy, kind, step) in configs() {
        let settings = TraceSettings {
            integrator: kind,
            step,
            max_steps: 1 << 20,
            exit: ExitMethod::Hermite,
            macro_cells: false,
            accuracy: grin_scene::DEFAULT_AUTO_ACCURACY,
            estimate_limit: grin_scene::DEFAULT_AUTO_ACCURACY,
            opl_control: false,
        };
        group.bench_function(BenchmarkId::new(kind.name(), policy), |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for (o, d) in &rays {
                    acc += trace_ray::<R>(f, &settings, *o, *d).opl;
                }
                std::hint::black_box(acc)
            })
        });
    }
    group.finish();
}

/// rk4 at fixed steps of 0.01 R and dopri under error control (auto 1e-7 rad), the same
/// beam ray by ray and in packets (grin_trace::packet: the same results bit for bit), one
/// thread.
fn bench_packets(c: &mut Criterion, name: &str, f: &dyn IndexField) {
    let (lo, hi) = f.bounds().aabb();
    let c0 = (lo + hi) * 0.5;
    let half = (hi - lo) * 0.5;
    // The beam scaled to the medium, along its longest axis (z for all three here).
    let rays: Vec<(DVec3, DVec3)> = beam()
        .into_iter()
        .map(|(o, d)| {
            let o = DVec3::new(c0.x + o.x * half.x, c0.y + o.y * half.y, lo.z - 1.0);
            (o, d)
        })
        .collect();
    let rk4 = TraceSettings {
        integrator: IntegratorKind::Rk4,
        step: StepSpec::Fixed(0.01 * f.bounds().radius()),
        max_steps: 1 << 20,
        exit: ExitMethod::Hermite,
        macro_cells: true,
        accuracy: grin_scene::DEFAULT_AUTO_ACCURACY,
        estimate_limit: grin_scene::DEFAULT_AUTO_ACCURACY,
        opl_control: false,
    };
    let dopri = TraceSettings {
        integrator: IntegratorKind::Adaptive,
        step: StepSpec::Auto(1e-7),
        ..rk4
    };
    for (method, settings) in [("rk4", rk4), ("dopri", dopri)] {
        bench_packet_pair(c, &format!("packets/{name}/{method}"), f, &settings, &rays);
    }
}

fn bench_packet_pair(
    c: &mut Criterion,
    group: &str,
    f: &dyn IndexField,
    settings: &TraceSettings,
    rays: &[(DVec3, DVec3)],
) {
    let mut group = c.benchmark_group(group);
    group.throughput(Throughput::Elements(rays.len() as u64));
    group.bench_function("ray-by-ray", |b| {
        b.iter(|| {
            let mut acc = 0.0;
            for (o, d) in rays {
                acc += trace_ray::<f64>(f, settings, *o, *d).opl;
            }
            std::hint::black_box(acc)
        })
    });
    group.bench_function("packets", |b| {
        b.iter(|| {
            let out = grin_trace::packet::trace_packets(f, settings, rays);
            std::hint::black_box(out.iter().map(|r| r.opl).sum::<f64>())
        })
    });
    group.finish();
}

fn benches(c: &mut Criterion) {
    let luneburg = field(
        FieldSpec::Luneburg { radius: None },
        BoundsSpec::Sphere {
            center: [0.0; 3],
            radius: 1.0,
        },
    );
    // Three hot-air blobs (delta n ~ -1e-4, like air 30 K above ambient).
    let blob = |a: f64, center: [f64; 3], s: f64| PlumeBlob { a, center, s };
    let plume = field(
        FieldSpec::Plume {
            plumes: vec![
                blob(1e-4, [0.0, -0.3, 0.0], 0.4),
                blob(6e-5, [0.2, 0.2, 0.1], 0.3),
                blob(4e-5, [-0.3, 0.5, -0.2], 0.25),
            ],
        },
        BoundsSpec::Box {
            min: [-1.0; 3],
            max: [1.0; 3],
        },
    );
    bench_packets(c, "luneburg", luneburg.as_ref());
    bench_packets(c, "plume", plume.as_ref());
    let rod = grin_field::expr::ExprField::benchmark_rod();
    bench_packets(c, "expr-rod", &rod);
    bench_field::<f64>(c, "luneburg", luneburg.as_ref(), "f64");
    bench_field::<f32>(c, "luneburg", luneburg.as_ref(), "f32");
    bench_field::<f64>(c, "plume", plume.as_ref(), "f64");
    bench_field::<f32>(c, "plume", plume.as_ref(), "f32");
}

criterion_group!(trace_benches, benches);
criterion_main!(trace_benches);
