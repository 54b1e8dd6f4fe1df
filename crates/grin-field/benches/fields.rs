//! The cost of one evaluation of n and grad n for every field kind, one point at a time
//! (`IndexField::sample`) and four at a time (`IndexField::sample4`, what the tracer's
//! ray packets call), on 4,096 random points inside each medium; for `expr`, the compiled
//! formula against the interpreter it is tested against.
//!
//! Each kind is the medium of one of data/scenes (and the fire cache of data/vdb); `baked`
//! is the noise sphere baked at 64^3.
//!
//! Run: `cargo bench -p grin-field --bench fields` (time per 4,096 points; per evaluation
//! divide by 4,096; figures in docs/benchmarks.md).

use std::hint::black_box;
use std::path::Path;
use std::sync::Arc;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use grin_field::bake::{BakeOptions, bake, random_points_inside};
use grin_field::expr::ExprField;
use grin_field::{IndexField, build_field};

/// (field kind, scene file) from the repository's data.
const SCENES: &[(&str, &str)] = &[
    ("grin-rod", "data/scenes/grin-rod.toml"),
    ("luneburg", "data/scenes/luneburg.toml"),
    ("maxwell-fish-eye", "data/scenes/maxwell-fish-eye.toml"),
    ("eaton", "data/scenes/eaton.toml"),
    ("exponential-atmosphere", "data/scenes/mirage.toml"),
    ("plume", "data/scenes/plume.toml"),
    ("expr", "data/scenes/paper-a.toml"),
    ("noise", "data/scenes/noise-sphere.toml"),
    ("vdb", "data/vdb/fire-haze.toml"),
];

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .and_then(Path::parent)
        .expect("the crate sits in crates/")
}

fn load(scene: &str) -> Arc<dyn IndexField> {
    let path = repo().join(scene);
    let parsed = grin_scene::load_scene(&path).expect("scene parses");
    let medium = parsed.medium.expect("scene has a medium");
    let dir = path.parent().expect("scene in a folder");
    build_field(&medium, dir).expect("field builds")
}

fn benches(c: &mut Criterion) {
    let mut fields: Vec<(String, Arc<dyn IndexField>)> = SCENES
        .iter()
        .map(|(kind, scene)| ((*kind).to_owned(), load(scene)))
        .collect();
    let noise = load("data/scenes/noise-sphere.toml");
    let opts = BakeOptions {
        resolution: Some(64),
        error_points: 200,
        ..Default::default()
    };
    let (baked, _) = bake(noise.as_ref(), &opts, &|_: &str, _: u64, _: u64| {}).expect("bake");
    fields.push(("baked".to_owned(), Arc::new(baked)));
    let rod = ExprField::benchmark_rod();

    const POINTS: usize = 4096;
    let mut g = c.benchmark_group("sample");
    g.throughput(Throughput::Elements(POINTS as u64));
    for (name, f) in &fields {
        let points = random_points_inside(f.bounds(), POINTS, 7);
        g.bench_function(format!("{name}/one"), |b| {
            b.iter(|| {
                points
                    .iter()
                    .map(|&p| f.sample(black_box(p)).n)
                    .sum::<f64>()
            })
        });
        let lanes: Vec<[[f64; 4]; 3]> = points
            .chunks_exact(4)
            .map(|q| {
                [
                    [q[0].x, q[1].x, q[2].x, q[3].x],
                    [q[0].y, q[1].y, q[2].y, q[3].y],
                    [q[0].z, q[1].z, q[2].z, q[3].z],
                ]
            })
            .collect();
        g.bench_function(format!("{name}/four"), |b| {
            b.iter(|| {
                let mut out = [[0.0; 4]; 4];
                let mut acc = 0.0;
                for p in &lanes {
                    f.sample4(black_box(*p), &mut out);
                    acc += out[0][0] + out[1][3];
                }
                acc
            })
        });
    }
    let points = random_points_inside(rod.bounds(), POINTS, 7);
    g.bench_function("expr-rod/compiled", |b| {
        b.iter(|| {
            points
                .iter()
                .map(|&p| rod.sample(black_box(p)).n)
                .sum::<f64>()
        })
    });
    g.bench_function("expr-rod/interpreted", |b| {
        b.iter(|| {
            points
                .iter()
                .map(|&p| rod.sample_interpreted(black_box(p)).n)
                .sum::<f64>()
        })
    });
    g.finish();
}

criterion_group!(fields_benches, benches);
criterion_main!(fields_benches);
