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

/// The file keeps every sample bit for bit, in both storages, both samplings and a
/// Catmull-Rom gradient of n; a dense reader refuses a sparse file by name.
#[test]
fn file_round_trip_is_exact() {
    let src = one_plume();
    let cases = [crate::baked::Storage::F32, crate::baked::Storage::I16]
        .into_iter()
        .flat_map(|s| {
            [
                (s, Interp::Trilinear, false),
                (s, Interp::Tricubic, false),
                (s, Interp::Tricubic, true),
            ]
        });
    for (storage, interp, of_n) in cases {
        let (f, _) = bake(
            &src,
            &SparseOptions {
                storage: Some(storage),
                top_bricks: Some(12),
                interp,
                ..Default::default()
            },
        );
        let f = f.with_gradient_of_n(of_n).expect("Catmull-Rom");
        let bytes = file::to_bytes(&f);
        let g = file::from_bytes(&bytes, "x.grinf").expect("read back");
        assert_eq!(g.interp(), interp);
        assert_eq!(g.gradient_of_n(), of_n);
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
        // An interpolation code beyond the three is refused by name (the checksum is
        // checked after the header's codes).
        let mut bad = bytes.clone();
        bad[36..40].copy_from_slice(&3u32.to_le_bytes());
        let e = file::from_bytes(&bad, "x.grinf").expect_err("code 3");
        assert!(
            e.to_string().contains("unknown interpolation code 3"),
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

/// One Catmull-Rom brick (`cells` a side, with its apron) of `f` (delta_n and its
/// gradient) over the unit cube.
fn catmull_rom_brick(cells: usize, f: impl Fn(DVec3) -> (f64, DVec3)) -> SparseField {
    let level = LEVEL_CELLS
        .iter()
        .position(|&c| c == cells)
        .expect("a level") as u8;
    let m = nodes_of(cells, 1);
    let h = 1.0 / cells as f64;
    let mut pool = Vec::with_capacity(m * m * m);
    for k in 0..m {
        for j in 0..m {
            for i in 0..m {
                let p = h * (DVec3::new(i as f64, j as f64, k as f64) - DVec3::ONE);
                let (d, g) = f(p);
                pool.push([d as f32, g.x as f32, g.y as f32, g.z as f32]);
            }
        }
    }
    let brick = Brick {
        at: [0; 3],
        level,
        offset: 0,
        scale: [1.0, 1.0],
        apron: 1,
    };
    SparseField::new(
        TopGrid {
            origin: DVec3::ZERO,
            edge: 1.0,
            dims: [1; 3],
        },
        vec![0],
        vec![brick],
        Pool::F32(pool),
        Bounds::Box {
            min: DVec3::ZERO,
            max: DVec3::ONE,
        },
        1.0,
        crate::baked::BakeProvenance::default(),
    )
    .expect("a field")
}

/// A Catmull-Rom field sampling its gradient of n: the gradient is the derivative of the
/// n it samples (central differences of n agree), where from its channels it is not.
#[test]
fn a_gradient_of_n_is_the_derivative_of_the_sampled_n() {
    let src = one_plume();
    let (f, _) = bake(
        &src,
        &SparseOptions {
            top_bricks: Some(8),
            interp: Interp::Tricubic,
            ..Default::default()
        },
    );
    let worst = |f: &SparseField| {
        let (mut worst, mut largest) = (0.0f64, 0.0f64);
        let e = 1e-4;
        for p in random_points_inside(src.bounds(), 3000, 9) {
            let s = f.sample(p);
            if s.n == f.ambient_index() {
                continue;
            }
            let fd = DVec3::new(
                f.n(p + DVec3::X * e) - f.n(p - DVec3::X * e),
                f.n(p + DVec3::Y * e) - f.n(p - DVec3::Y * e),
                f.n(p + DVec3::Z * e) - f.n(p - DVec3::Z * e),
            ) / (2.0 * e);
            worst = worst.max((fd - s.grad_n).abs().max_element());
            largest = largest.max(s.grad_n.abs().max_element());
        }
        worst / largest
    };
    let channels = worst(&f);
    let of_n = worst(&f.clone().with_gradient_of_n(true).expect("Catmull-Rom"));
    eprintln!(
        "gradient against central differences of n: channels {channels:.2e}, of n {of_n:.2e}"
    );
    assert!(of_n < 1e-3, "{of_n:e}");
    assert!(
        channels > 3.0 * of_n,
        "channels {channels:e}, of n {of_n:e}"
    );
    // Only Catmull-Rom bricks have one.
    let (lin, _) = bake(
        &src,
        &SparseOptions {
            top_bricks: Some(8),
            ..Default::default()
        },
    );
    assert!(lin.with_gradient_of_n(true).is_err());
}

/// Catmull-Rom reproduces quadratics (to f32 rounding) and converges at third order in n
/// and in the gradient's channels; the field reports it samples tricubically.
#[test]
fn catmull_rom_bricks_hold_quadratics_and_converge_at_third_order() {
    let quadratic = |p: DVec3| {
        let d = 0.01 * (p.x * p.x + 2.0 * p.y * p.y - p.z * p.z + p.x * p.y);
        let g = 0.01 * DVec3::new(2.0 * p.x + p.y, 4.0 * p.y + p.x, -2.0 * p.z);
        (d, g)
    };
    let f = catmull_rom_brick(8, quadratic);
    assert_eq!(f.interp(), crate::baked::Interp::Tricubic);
    let points = random_points_inside(f.bounds(), 2000, 3);
    let worst = |f: &SparseField, exact: &dyn Fn(DVec3) -> (f64, DVec3)| {
        points.iter().fold((0.0f64, 0.0f64), |(wn, wg), &p| {
            let s = f.sample(p);
            let (d, g) = exact(p);
            (
                wn.max((s.n - 1.0 - d).abs()),
                wg.max((s.grad_n - g).length()),
            )
        })
    };
    let (en, eg) = worst(&f, &quadratic);
    assert!(
        en < 1e-8 && eg < 1e-7,
        "quadratic: n off by {en:e}, grad by {eg:e}"
    );
    let smooth = |p: DVec3| {
        let (a, b, c) = (2.0 * p.x + 1.0, 3.0 * p.y, 2.5 * p.z - 0.5);
        let d = 0.01 * a.sin() * b.cos() * c.sin();
        let g = 0.01
            * DVec3::new(
                2.0 * a.cos() * b.cos() * c.sin(),
                -3.0 * a.sin() * b.sin() * c.sin(),
                2.5 * a.sin() * b.cos() * c.cos(),
            );
        (d, g)
    };
    let errors: Vec<(f64, f64)> = [8, 16, 32]
        .iter()
        .map(|&c| worst(&catmull_rom_brick(c, smooth), &smooth))
        .collect();
    eprintln!("Catmull-Rom at 8, 16, 32 cells: (n, grad) errors {errors:?}");
    for w in errors.windows(2) {
        let (on, og) = ((w[0].0 / w[1].0).log2(), (w[0].1 / w[1].1).log2());
        assert!(
            on > 2.6 && og > 2.6,
            "orders {on:.2} (n) and {og:.2} (grad) from {errors:?}"
        );
    }
}

/// At the same budget a Catmull-Rom bake meets it at independent points, as a trilinear
/// one does, in a fraction of the bytes (a smooth plume: third order against second).
#[test]
fn catmull_rom_bakes_meet_the_budget_in_fewer_bytes() {
    let src = one_plume();
    for budget in [1e-3, 1e-4] {
        let bytes = [
            crate::baked::Interp::Trilinear,
            crate::baked::Interp::Tricubic,
        ]
        .map(|interp| {
            let (f, r) = bake(
                &src,
                &SparseOptions {
                    error_budget: budget,
                    storage: Some(crate::baked::Storage::F32),
                    interp,
                    ..Default::default()
                },
            );
            assert_eq!(f.interp(), interp);
            let mut worst = 0.0f64;
            for p in random_points_inside(src.bounds(), 20_000, 99) {
                worst = worst.max((f.sample(p).n - src.n(p)).abs());
            }
            let rel = worst / r.delta_n_range;
            assert!(
                rel <= budget && r.meets_budget,
                "{} at {budget}: independent relative error {rel}",
                interp.name()
            );
            r.bytes
        });
        eprintln!(
            "at {budget}: trilinear {} bytes, Catmull-Rom {}",
            bytes[0], bytes[1]
        );
        assert!(
            bytes[1] * 3 < bytes[0],
            "at {budget}: trilinear {} bytes, Catmull-Rom {}",
            bytes[0],
            bytes[1]
        );
    }
}

/// Catmull-Rom rings past a sharp edge; a sample is clamped to the nodes' delta_n range,
/// flat (zero gradient) where clamped, as grin's sampling of a VDB grid is. A brick's
/// records must agree on their apron.
#[test]
fn catmull_rom_is_clamped_to_its_nodes_and_aprons_agree() {
    // A step in x: 0 below x = 0.5, -0.01 above.
    let step = |p: DVec3| (if p.x < 0.5 { 0.0 } else { -0.01 }, DVec3::ZERO);
    let f = catmull_rom_brick(8, step);
    assert_eq!(f.delta_range(), (-0.01, 0.0));
    let (mut clamped, mut lowest, mut highest) = (0, f64::INFINITY, f64::NEG_INFINITY);
    for i in 0..=400 {
        let p = DVec3::new(i as f64 / 400.0, 0.37, 0.61);
        let s = f.sample(p);
        lowest = lowest.min(s.n - 1.0);
        highest = highest.max(s.n - 1.0);
        if s.n - 1.0 == 0.0 || s.n - 1.0 == f64::from(-0.01f32) {
            assert_eq!(s.grad_n, DVec3::ZERO, "flat where clamped at {p}");
            clamped += 1;
        }
    }
    assert!(
        lowest >= f64::from(-0.01f32) && highest <= 0.0 && clamped > 0,
        "delta_n {lowest} ..= {highest}, {clamped} clamped"
    );
    // Raw Catmull-Rom of the same nodes rings past them (what the clamp is for).
    let b = f.bricks()[0];
    let raw = f.catmull_rom(&b, DVec3::new(2.5, 3.0, 4.0));
    assert!(raw[0] > 0.0, "ringing {}", raw[0]);
    // Mixed aprons are a crafted file's, refused by name.
    let mut bricks = vec![
        b,
        Brick {
            at: [1, 0, 0],
            offset: b.voxel_count(),
            apron: 0,
            ..b
        },
    ];
    let top = TopGrid {
        origin: DVec3::ZERO,
        edge: 1.0,
        dims: [2, 1, 1],
    };
    let len = bricks[0].voxel_count() + bricks[1].voxel_count();
    let e = check_parts(&top, &[0, 1], &bricks, len).expect_err("mixed aprons");
    assert!(
        e.contains("brick 1 has an apron of 0 node layers where brick 0 has 1"),
        "{e}"
    );
    bricks[1].apron = 2;
    bricks[0].apron = 2;
    assert!(check_parts(&top, &[0, 1], &bricks, len).is_err());
}

/// A budget the storage cannot meet (i16 rounds to ~1e-5 of the range) is refused at the
/// memory cap, wherever the bake passes it (the rounds that bake bricks again finer count
/// against it too: they once grew a Catmull-Rom bake of this plume to 17 GB under a 1 GB
/// cap, `grin bake --sparse --interp tricubic --storage i16 --error 1e-6`).
#[test]
fn refining_stops_at_the_memory_cap() {
    let e = bake_sparse(
        &one_plume(),
        &SparseOptions {
            error_budget: 1e-6,
            storage: Some(crate::baked::Storage::I16),
            interp: Interp::Tricubic,
            max_memory: 48 << 20,
            ..Default::default()
        },
        &no_progress,
    )
    .expect_err("over the cap");
    assert!(
        e.to_string()
            .starts_with("a sparse bake needs more than the memory cap of 50331648 bytes"),
        "{e}"
    );
}

/// An all-ambient medium baked Catmull-Rom has no brick to say so, and keeps it: in the
/// field and through its file. A header's measured errors must be finite and not negative.
#[test]
fn an_empty_catmull_rom_bake_keeps_its_sampling_and_errors_are_checked() {
    let uniform = crate::analytic::Uniform::new(
        Bounds::Box {
            min: DVec3::splat(-1.0),
            max: DVec3::splat(1.0),
        },
        1.0003,
        1.0003,
    )
    .expect("uniform");
    let (f, r) = bake(
        &uniform,
        &SparseOptions {
            interp: Interp::Tricubic,
            ..Default::default()
        },
    );
    assert_eq!(
        (r.active_bricks, f.interp(), f.apron()),
        (0, Interp::Tricubic, 1)
    );
    let mut bytes = file::to_bytes(&f);
    let g = file::from_bytes(&bytes, "u.grinf").expect("read back");
    assert_eq!(g.interp(), Interp::Tricubic);
    // Sampled trilinear after all: no gradient of n is left to write (code 1 would read
    // as Catmull-Rom).
    let of_n = g.with_gradient_of_n(true).expect("Catmull-Rom");
    let lin = of_n.with_apron(0).expect("no brick");
    assert!(!lin.gradient_of_n());
    let back = file::from_bytes(&file::to_bytes(&lin), "u.grinf").expect("read back");
    assert_eq!(
        (back.interp(), back.gradient_of_n()),
        (Interp::Trilinear, false)
    );
    bytes[136..144].copy_from_slice(&f64::NAN.to_le_bytes());
    let n = bytes.len() - 4;
    let crc = crc32fast::hash(&bytes[..n]);
    bytes[n..].copy_from_slice(&crc.to_le_bytes());
    let e = file::from_bytes(&bytes, "u.grinf").expect_err("NaN error");
    assert!(
        e.to_string().contains("must be finite and not negative"),
        "{e}"
    );
}
