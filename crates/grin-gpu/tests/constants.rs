//! Every constant the WGSL kernel mirrors from Rust has the same value on both sides:
//! the integer kind codes and flags of gpu_data.rs, and the tolerances, caps and floors of the CPU
//! twin (grin-trace's step controller, exit search, march and path loop). The kernel is
//! parsed with naga and its module constants evaluated; a constant missing on either side
//! or differing fails, so a one-line change to either file shows up here.

use std::collections::BTreeMap;

use grin_gpu::gpu_data as g;
use grin_trace::RayStatus;
use grin_trace::render::shade::{AMBIENT_SKY_WEIGHT, EVENTS_PER_DEPTH, status_code};
use grin_trace::{boundary, step, trace};

/// The render kernel's module constants with a scalar value, by name.
fn wgsl_constants() -> BTreeMap<String, f64> {
    constants_of(grin_gpu::shaders::RENDER_WGSL)
}

/// The module constants of the WGSL `source` with a scalar value, by name.
fn constants_of(source: &str) -> BTreeMap<String, f64> {
    let module = naga::front::wgsl::parse_str(source).expect("WGSL parses");
    let mut out = BTreeMap::new();
    for (_, c) in module.constants.iter() {
        let Some(name) = &c.name else { continue };
        let value = match module.global_expressions[c.init] {
            naga::Expression::Literal(lit) => match lit {
                naga::Literal::F32(v) => f64::from(v),
                naga::Literal::U32(v) => f64::from(v),
                naga::Literal::I32(v) => f64::from(v),
                naga::Literal::F64(v) => v,
                naga::Literal::AbstractFloat(v) => v,
                naga::Literal::AbstractInt(v) => v as f64,
                _ => continue,
            },
            _ => continue,
        };
        out.insert(name.clone(), value);
    }
    out
}

/// Where the CPU keeps an f64 and the GPU an f32, they agree to f32 rounding.
fn same(rust: f64, wgsl: f64) -> bool {
    rust == wgsl || ((rust - wgsl).abs() <= f64::from(f32::EPSILON) * rust.abs())
}

#[test]
fn mirrored_constants_have_the_same_values() {
    let wgsl = wgsl_constants();
    let u = f64::from;
    let mirrored: Vec<(&str, f64)> = vec![
        ("INTEGRATOR_EULER", u(g::INTEGRATOR_EULER)),
        (
            "INTEGRATOR_SYMPLECTIC_EULER",
            u(g::INTEGRATOR_SYMPLECTIC_EULER),
        ),
        ("INTEGRATOR_VERLET", u(g::INTEGRATOR_VERLET)),
        ("INTEGRATOR_SHARMA", u(g::INTEGRATOR_SHARMA)),
        ("INTEGRATOR_RK4", u(g::INTEGRATOR_RK4)),
        ("INTEGRATOR_ADAPTIVE", u(g::INTEGRATOR_ADAPTIVE)),
        ("STEP_FIXED", u(g::STEP_FIXED)),
        ("STEP_HEURISTIC", u(g::STEP_HEURISTIC)),
        ("STEP_ADAPTIVE", u(g::STEP_ADAPTIVE)),
        ("FLAG_HAS_MEDIUM", u(g::FLAG_HAS_MEDIUM)),
        ("FLAG_MACRO_CELLS", u(g::FLAG_MACRO_CELLS)),
        ("FLAG_JITTER", u(g::FLAG_JITTER)),
        ("FLAG_BEND_SHADOWS", u(g::FLAG_BEND_SHADOWS)),
        ("FLAG_OUTSIDE_AMBIENT", u(g::FLAG_OUTSIDE_AMBIENT)),
        ("FLAG_TRICUBIC", u(g::FLAG_TRICUBIC)),
        ("FLAG_EXIT_HERMITE", u(g::FLAG_EXIT_HERMITE)),
        ("FLAG_MEDIUM_OBJECTS", u(g::FLAG_MEDIUM_OBJECTS)),
        ("FLAG_HAS_OBJECTS", u(g::FLAG_HAS_OBJECTS)),
        ("FLAG_SPARSE", u(g::FLAG_SPARSE)),
        ("FLAG_FIELD_SNORM", u(g::FLAG_FIELD_SNORM)),
        ("FLAG_GRADIENT_OF_N", u(g::FLAG_GRADIENT_OF_N)),
        ("SPARSE_ROW", grin_gpu::field::SPARSE_ROW as f64),
        ("PASS_ALL", u(g::PASS_ALL)),
        ("PASS_FIRST", u(g::PASS_FIRST)),
        ("PASS_MEDIUM", u(g::PASS_MEDIUM)),
        ("SHAPE_SPHERE", u(g::SHAPE_SPHERE)),
        ("SHAPE_PLANE", u(g::SHAPE_PLANE)),
        ("SHAPE_BOX", u(g::SHAPE_BOX)),
        ("MATERIAL_DIFFUSE", u(g::MATERIAL_DIFFUSE)),
        ("MATERIAL_CHECKER", u(g::MATERIAL_CHECKER)),
        ("MATERIAL_MIRROR", u(g::MATERIAL_MIRROR)),
        ("MATERIAL_METAL", u(g::MATERIAL_METAL)),
        ("MATERIAL_GLASS", u(g::MATERIAL_GLASS)),
        ("LIGHT_KIND_POINT", u(g::LIGHT_KIND_POINT)),
        ("LIGHT_KIND_DIRECTIONAL", u(g::LIGHT_KIND_DIRECTIONAL)),
        ("BOUNDS_KIND_SPHERE", u(g::BOUNDS_KIND_SPHERE)),
        ("BOUNDS_KIND_BOX", u(g::BOUNDS_KIND_BOX)),
        ("SKY_KIND_GRADIENT", u(g::SKY_KIND_GRADIENT)),
        ("SKY_KIND_MAP", u(g::SKY_KIND_MAP)),
        // The CPU twin's numbers.
        ("ADAPTIVE_MAX_DS_REL", step::ADAPTIVE_MAX_DS_REL),
        ("ADAPTIVE_MIN_DS_REL", step::ADAPTIVE_MIN_DS_REL),
        ("ADAPTIVE_INITIAL_DS_REL", step::ADAPTIVE_INITIAL_DS_REL),
        ("ADAPTIVE_MIN_DS_EPS", step::ADAPTIVE_MIN_DS_EPS),
        ("ADAPTIVE_TOL_FLOOR_EPS", step::ADAPTIVE_TOL_FLOOR_EPS),
        ("SAFETY", step::SAFETY),
        ("MAX_GROWTH", step::MAX_GROWTH),
        ("MIN_SHRINK", step::MIN_SHRINK),
        ("MAX_REJECTIONS", u(step::MAX_REJECTIONS)),
        (
            "MIN_JITTER_FRACTION",
            f64::from(grin_render::scene::MIN_JITTER_FRACTION),
        ),
        ("MAX_BISECTIONS", u(boundary::MAX_BISECTIONS)),
        ("HERMITE_SCAN", u(boundary::HERMITE_SCAN)),
        ("EXIT_TOL_REL", boundary::EXIT_TOL_REL),
        ("EXIT_TOL_EPS", boundary::EXIT_TOL_EPS),
        ("MIN_SPAN_REL", trace::MIN_SPAN_REL),
        ("MIN_FLIGHT_VOXELS", trace::MIN_FLIGHT_VOXELS),
        ("ENTRY_NUDGE_EPS", trace::ENTRY_NUDGE_EPS),
        ("ENTRY_NUDGE_MIN_COS", trace::ENTRY_NUDGE_MIN_COS),
        ("EXIT_NEWTON_ITERATIONS", u(trace::EXIT_NEWTON_ITERATIONS)),
        ("EXCURSION_ITERATIONS", u(boundary::EXCURSION_ITERATIONS)),
        ("EXCURSION_SLACK_TOLS", boundary::EXCURSION_SLACK_TOLS),
        (
            "LENGTH_SCALE_STEP_FRACTION",
            step::LENGTH_SCALE_STEP_FRACTION,
        ),
        ("FEATURE_STEP_FRACTION", step::FEATURE_STEP_FRACTION),
        ("F32_EPSILON", f64::from(f32::EPSILON)),
        ("AMBIENT_SKY_WEIGHT", AMBIENT_SKY_WEIGHT),
        ("EVENTS_PER_DEPTH", u(EVENTS_PER_DEPTH)),
        ("STATUS_MISSED", f64::from(status_code(RayStatus::Missed))),
        ("STATUS_EXITED", f64::from(status_code(RayStatus::Exited))),
        (
            "STATUS_ABSORBED",
            f64::from(status_code(RayStatus::Absorbed)),
        ),
        (
            "STATUS_MAX_STEPS",
            f64::from(status_code(RayStatus::MaxSteps)),
        ),
        ("STATUS_ERROR", f64::from(status_code(RayStatus::Error))),
        ("STATUS_ERROR", u(g::STATUS_ERROR)),
        (
            "STATUS_DEGRADED",
            f64::from(status_code(RayStatus::Degraded)),
        ),
        ("POSITION_SAFETY", grin_trace::estimate::POSITION_SAFETY),
        ("CROSSING_FACTOR", grin_trace::estimate::CROSSING_FACTOR),
    ];
    let mut problems = Vec::new();
    for (name, rust) in &mirrored {
        match wgsl.get(*name) {
            None => problems.push(format!("{name}: not a constant of the WGSL kernel")),
            Some(&w) if !same(*rust, w) => problems.push(format!("{name}: Rust {rust}, WGSL {w}")),
            Some(_) => {}
        }
    }
    assert!(
        problems.is_empty(),
        "mirrored constants differ:\n{}",
        problems.join("\n")
    );
    assert!(mirrored.len() >= 60, "{}", mirrored.len());
}

/// Constants that differ on purpose, as data: each says why. A change to one of them on
/// either side must update this list.
/// The kernels that count a frame's rays (the viewer's image, the packed read-back) know
/// `error` and the loop-limit suspects' steps as the renderer does.
#[test]
fn the_counting_kernels_mirror_the_status_and_the_loop_limit() {
    for (name, source) in [
        ("view.wgsl", grin_gpu::shaders::VIEW_WGSL),
        ("channels.wgsl", grin_gpu::shaders::CHANNELS_WGSL),
    ] {
        let c = constants_of(source);
        assert_eq!(
            c.get("STATUS_ERROR"),
            Some(&f64::from(g::STATUS_ERROR)),
            "{name}"
        );
        assert_eq!(
            c.get("LOOP_LIMIT_SUSPECT_STEPS"),
            Some(&f64::from(grin_gpu::device::LOOP_LIMIT_SUSPECT_STEPS)),
            "{name}"
        );
    }
}

#[test]
fn deliberate_differences_are_the_documented_ones() {
    let wgsl = wgsl_constants();
    // SURFACE_EPS: f64 1e-6 on the CPU; in f32 at scene scale ~10 an ulp is ~1e-6, so the
    // GPU pushes rays 1e-4 off a surface (medium.wgsl).
    assert_eq!(grin_trace::render::medium::SURFACE_EPS, 1e-6);
    assert!(same(1e-4, wgsl["SURFACE_EPS"]), "{}", wgsl["SURFACE_EPS"]);
}
