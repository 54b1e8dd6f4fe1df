use glam::DVec3;
use grin_scene::PlumeBlob;

use super::bake::{SparseOptions, bake_sparse};
use super::*;
use crate::analytic::plume::Plume;
use crate::bake::random_points_inside;

fn no_progress(_: &str, _: u64, _: u64) {}

/// Eight plumes near the corners of a 1000-unit cube (data/scenes/eight-plumes.toml).
fn eight_plumes() -> Plume {
    let c = [
        ([120.0, 110.0, 130.0], 20.0),
        ([880.0, 120.0, 110.0], 24.0),
        ([115.0, 885.0, 120.0], 18.0),
        ([890.0, 880.0, 125.0], 22.0),
        ([125.0, 115.0, 875.0], 20.0),
        ([870.0, 125.0, 890.0], 26.0),
        ([110.0, 870.0, 880.0], 19.0),
        ([885.0, 890.0, 870.0], 21.0),
    ];
    let blobs: Vec<PlumeBlob> = c
        .iter()
        .map(|&(center, s)| PlumeBlob {
            a: 0.004,
            center,
            s,
        })
        .collect();
    Plume::new(
        Bounds::Box {
            min: DVec3::ZERO,
            max: DVec3::splat(1000.0),
        },
        1.0,
        &blobs,
    )
    .expect("plume")
}

/// One plume of width 0.3 in a 4-unit box.
fn one_plume() -> Plume {
    Plume::new(
        Bounds::Box {
            min: DVec3::splat(-2.0),
            max: DVec3::splat(2.0),
        },
        1.0,
        &[PlumeBlob {
            a: 0.01,
            center: [0.3, -0.2, 0.1],
            s: 0.3,
        }],
    )
    .expect("plume")
}

fn bake(src: &dyn IndexField, opts: &SparseOptions) -> (SparseField, super::bake::SparseReport) {
    match bake_sparse(src, opts, &no_progress) {
        Ok(x) => x,
        Err(e) => panic!("{e}"),
    }
}

fn level_at(f: &SparseField, p: DVec3) -> Option<u8> {
    let g = (p - f.top().origin) / f.top().edge;
    let at = [g.x as usize, g.y as usize, g.z as usize];
    let e = f.table()[f.top().index(at)];
    (e != EMPTY).then(|| f.bricks()[e as usize].level)
}

/// Far from the plume the field is exactly ambient with no gradient, a ray there flies
/// straight to the first active brick, and inside an active brick it does not fly.
#[test]
fn empty_bricks_are_ambient_and_flown_over() {
    let src = one_plume();
    let (f, r) = bake(
        &src,
        &SparseOptions {
            top_bricks: Some(16),
            ..Default::default()
        },
    );
    assert!(r.meets_budget);
    assert!(r.proven_empty, "a plume proves its empty bricks");
    assert!(
        r.active_bricks < r.total_bricks / 4,
        "{} of {}",
        r.active_bricks,
        r.total_bricks
    );
    let far = DVec3::new(-1.9, 1.9, -1.9);
    assert_eq!(level_at(&f, far), None);
    let s = f.sample(far);
    assert_eq!((s.n, s.grad_n), (1.0, DVec3::ZERO));
    // Along +x at the plume's y, z: the span ends at an active brick's face, before the
    // plume's centre, and past where the source differs from ambient by the crop's share.
    let start = DVec3::new(-1.9, -0.2, 0.1);
    let span = f
        .homogeneous_span(start, DVec3::X)
        .expect("an empty brick flies");
    let end = start + DVec3::X * span;
    assert!(
        end.x < 0.3,
        "the flight ends at {end}, past the plume's centre"
    );
    let face = (end.x - f.top().origin.x) / f.top().edge;
    assert!(
        (face - face.round()).abs() < 1e-9,
        "ends at a brick face ({face})"
    );
    assert!(level_at(&f, end + DVec3::X * 1e-6).is_some());
    let thr = 0.1 * 1e-3 * r.delta_n_range;
    for k in 0..100 {
        let p = start + DVec3::X * (span * f64::from(k) / 100.0);
        assert!(
            (src.n(p) - 1.0).abs() <= thr,
            "the flight passes n - 1 = {} at {p}",
            src.n(p) - 1.0
        );
    }
    assert_eq!(
        f.homogeneous_span(DVec3::new(0.3, -0.2, 0.1), DVec3::X),
        None
    );
}

/// Each brick is as fine as its content needs: the plume's core gets a finer level than
/// its tail, the error at random points meets the budget, and a tighter budget costs more
/// bytes, not a missed budget.
#[test]
fn levels_follow_the_content_and_the_budget() {
    let src = one_plume();
    let mut bytes = Vec::new();
    for budget in [1e-2, 1e-3, 1e-4] {
        let (f, r) = bake(
            &src,
            &SparseOptions {
                error_budget: budget,
                storage: Some(crate::baked::Storage::F32),
                ..Default::default()
            },
        );
        let core = level_at(&f, DVec3::new(0.3, -0.2, 0.1)).expect("core");
        let tail = level_at(&f, DVec3::new(0.3 + 0.75, -0.2, 0.1)).expect("tail");
        assert!(
            core > tail,
            "budget {budget}: core level {core}, tail level {tail}"
        );
        // Independent random points.
        let mut worst = 0.0f64;
        for p in random_points_inside(src.bounds(), 20_000, 99) {
            worst = worst.max((f.sample(p).n - src.n(p)).abs());
        }
        let rel = worst / r.delta_n_range;
        assert!(
            rel <= budget,
            "budget {budget}: independent relative error {rel}"
        );
        assert!(r.meets_budget && r.relative_error <= budget);
        bytes.push(r.bytes);
    }
    assert!(bytes[0] < bytes[1] && bytes[1] < bytes[2], "{bytes:?}");
}

/// A field that proves nothing (an `expr` formula) is probed brick by brick, and the bake
/// still meets the budget.
#[test]
fn unproven_fields_are_probed() {
    let src = crate::expr::ExprField::new(
        "1 + 0.01*exp(-((x-0.3)^2 + (y+0.2)^2 + z^2)/0.09)",
        Bounds::Box {
            min: DVec3::splat(-2.0),
            max: DVec3::splat(2.0),
        },
        1.0,
        0.0,
    )
    .expect("expr");
    let (f, r) = bake(&src, &SparseOptions::default());
    assert!(!r.proven_empty);
    assert!(r.meets_budget && r.active_bricks < r.total_bricks / 4);
    assert!(f.sample(DVec3::new(0.3, -0.2, 0.0)).n > 1.0099);
}

/// The file keeps every sample bit for bit, in both storages; a dense reader refuses a
/// sparse file by name.
#[test]
fn file_round_trip_is_exact() {
    let src = one_plume();
    for storage in [crate::baked::Storage::F32, crate::baked::Storage::I16] {
        let (f, _) = bake(
            &src,
            &SparseOptions {
                storage: Some(storage),
                top_bricks: Some(12),
                ..Default::default()
            },
        );
        let bytes = file::to_bytes(&f);
        let g = file::from_bytes(&bytes, "x.grinf").expect("read back");
        assert_eq!(g.bricks(), f.bricks());
        assert_eq!(g.table(), f.table());
        assert_eq!(g.provenance(), f.provenance());
        for p in random_points_inside(src.bounds(), 2000, 5) {
            assert_eq!(f.sample(p), g.sample(p), "{storage:?} at {p}");
        }
        let e = crate::grinf::from_bytes(&bytes, "x.grinf").expect_err("dense reader");
        assert!(
            e.to_string()
                .starts_with("x.grinf: a sparse .grinf (version 2)"),
            "{e}"
        );
    }
}

/// A cap the active bricks cannot fit under is a clear error.
#[test]
fn memory_cap_is_a_clear_error() {
    let e = bake_sparse(
        &eight_plumes(),
        &SparseOptions {
            max_memory: 20 << 20,
            ..Default::default()
        },
        &no_progress,
    )
    .expect_err("over the cap");
    let text = e.to_string();
    assert!(
        text.starts_with("a sparse bake needs more than the memory cap of 20971520 bytes"),
        "{text}"
    );
}
