//! Procedural noise (the paper's baseline: fBm with a central-difference gradient at every
//! Runge-Kutta stage) vs the same medium baked: per-sample cost, the cost of a frame of
//! rays marched with a fixed-step RK4 (4 samples per step, the same for both), and bake
//! time per resolution.
//!
//! Run: `cargo bench -p grin-field --bench bake` (numbers in docs/grinf.md).

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use grin_field::bake::{BakeOptions, bake, random_points_inside};
use grin_field::baked::{Interp, Storage};
use grin_field::noise::NoiseField;
use grin_field::{Bounds, IndexField};
use grin_scene::{NoiseSpec, NoiseType};

/// The medium of data/scenes/noise-sphere.toml.
fn noise_field() -> NoiseField {
    let spec = NoiseSpec {
        noise: NoiseType::Fbm,
        octaves: 3,
        frequency: 1.5,
        amplitude: 0.02,
        seed: 7,
        lacunarity: 2.0,
        persistence: 0.5,
        envelope: 0.3,
        drift: [0.0, 0.25, 0.0],
        t: 0.0,
    };
    let bounds = Bounds::Sphere {
        center: DVec3::ZERO,
        radius: 1.0,
    };
    NoiseField::new(&spec, bounds, 1.0).expect("valid noise spec")
}

/// Step of the frame's RK4 march (world units), the scene's fixed step.
const STEP: f64 = 0.02;
/// Rays per frame: a 16 x 16 grid of parallel rays.
const SIDE: usize = 16;

/// March a 16 x 16 frame of rays along +z through the ball with RK4 on r'' = n grad n.
fn frame(field: &dyn IndexField) -> f64 {
    let mut acc = 0.0;
    for j in 0..SIDE {
        for i in 0..SIDE {
            let x = -0.9 + 1.8 * (i as f64 + 0.5) / SIDE as f64;
            let y = -0.9 + 1.8 * (j as f64 + 0.5) / SIDE as f64;
            if x * x + y * y > 0.81 {
                continue;
            }
            let z0 = -(1.0 - x * x - y * y).sqrt();
            let mut r = DVec3::new(x, y, z0);
            let mut t = DVec3::Z * field.sample(r).n;
            let d = |p: DVec3| field.sample(p).n_grad_n();
            let h = STEP;
            while r.length_squared() <= 1.0 {
                let k1 = d(r);
                let k2 = d(r + t * (h / 2.0) + k1 * (h * h / 8.0));
                let k3 = d(r + t * (h / 2.0) + k2 * (h * h / 8.0));
                let k4 = d(r + t * h + k3 * (h * h / 2.0));
                r += t * h + (k1 + k2 + k3) * (h * h / 6.0);
                t += (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0);
            }
            acc += r.x + t.y;
        }
    }
    acc
}

fn benches(c: &mut Criterion) {
    let procedural = noise_field();
    let quiet = |_: &str, _: u64, _: u64| {};
    let mut baked = Vec::new();
    for (res, interp) in [
        (64, Interp::Trilinear),
        (128, Interp::Trilinear),
        (128, Interp::Tricubic),
    ] {
        let opts = BakeOptions {
            resolution: Some(res),
            interp,
            storage: Some(Storage::I16),
            error_points: 2000,
            ..Default::default()
        };
        let (field, report) = bake(&procedural, &opts, &quiet).expect("bake");
        eprintln!(
            "baked {res} {}: {:?} {} bytes, max |dn err| {:.2e}, bake {:.2} s",
            interp.name(),
            report.dims,
            report.bytes,
            report.errors.max_err_n,
            report.seconds
        );
        baked.push((format!("baked-{res}-{}", interp.name()), field));
    }
    let points = random_points_inside(procedural.bounds(), 4096, 7);

    let mut g = c.benchmark_group("sample");
    g.bench_function("procedural-fbm", |b| {
        b.iter(|| {
            points
                .iter()
                .map(|&p| procedural.sample(black_box(p)).n)
                .sum::<f64>()
        })
    });
    for (name, f) in &baked {
        g.bench_function(name.as_str(), |b| {
            b.iter(|| {
                points
                    .iter()
                    .map(|&p| f.sample(black_box(p)).n)
                    .sum::<f64>()
            })
        });
    }
    g.finish();

    let mut g = c.benchmark_group("frame");
    g.sample_size(10);
    g.bench_function("procedural-fbm", |b| {
        b.iter(|| frame(black_box(&procedural)))
    });
    for (name, f) in &baked {
        g.bench_function(name.as_str(), |b| b.iter(|| frame(black_box(f))));
    }
    g.finish();

    let mut g = c.benchmark_group("bake");
    g.sample_size(10);
    for res in [32, 64, 128] {
        let opts = BakeOptions {
            resolution: Some(res),
            storage: Some(Storage::I16),
            error_points: 100,
            ..Default::default()
        };
        g.bench_function(format!("noise-{res}"), |b| {
            b.iter(|| bake(&procedural, &opts, &quiet).expect("bake").1.bytes)
        });
    }
    g.finish();
}

criterion_group!(bake_benches, benches);
criterion_main!(bake_benches);
