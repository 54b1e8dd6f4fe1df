use std::path::Path;
use std::sync::Arc;

use super::*;
use grin_render::scene::RenderScene;

/// The Luneburg lens (radius 1) seen from z = -4, with `render` lines added.
fn lens(render: &str) -> RenderScene {
    let text = format!(
        "[camera]\nposition = [0.0, 0.0, -4.0]\nlook_at = [0.0, 0.0, 0.0]\n\
             [medium]\nbounds = {{ sphere = {{ center = [0.0, 0.0, 0.0], radius = 1.0 }} }}\n\
             field = {{ kind = \"luneburg\" }}\n[render]\nwidth = 64\nheight = 36\n{render}"
    );
    let scene = grin_scene::parse_scene(&text, Path::new("lens.toml")).expect("scene");
    let medium = scene.medium.as_ref().expect("medium");
    let field: Arc<dyn IndexField> =
        grin_field::build_field(medium, Path::new(".")).expect("field");
    RenderScene::new(&scene, Path::new("."), Some(field)).expect("render scene")
}

/// A plume in a corner of a large medium (a cache whose smoke fills a corner of its
/// bounds): most of a coarse grid of camera rays crosses only ambient air, so the
/// pilots are picked among rays that cross the plume first.
#[test]
fn pilots_go_where_the_index_varies() {
    let text = "[camera]\nposition = [0.0, 0.0, -8.0]\nlook_at = [0.0, 0.0, 0.0]\n\
             [medium]\nbounds = { box = { min = [-2.0, -2.0, -2.0], max = [2.0, 2.0, 2.0] } }\n\
             field = { kind = \"plume\", plumes = [ { a = 1e-3, center = [1.4, 1.4, 0.0], s = 0.15 } ] }\n\
             [render]\nwidth = 256\nheight = 256\n";
    let scene = grin_scene::parse_scene(text, Path::new("corner.toml")).expect("scene");
    let medium = scene.medium.as_ref().expect("medium");
    let field: Arc<dyn IndexField> =
        grin_field::build_field(medium, Path::new(".")).expect("field");
    let rs = RenderScene::new(&scene, Path::new("."), Some(field.clone())).expect("scene");
    let pilots = scene_pilots(&rs);
    let crossing = pilots
        .iter()
        .filter(|&&(o, d)| crosses_variation(field.as_ref(), o, d))
        .count();
    // Of the plain 8x8 grid, few rays cross the plume's few percent of the view.
    let grid = camera_pilots(&rs.camera, 64)
        .into_iter()
        .filter(|&(o, d)| crosses_variation(field.as_ref(), o, d))
        .count();
    eprintln!(
        "pilots crossing the plume: {crossing} of {} (a plain grid: {grid} of 64)",
        pilots.len()
    );
    assert!(pilots.len() >= 48, "{} pilots", pilots.len());
    assert!(crossing > grid && crossing >= 4, "{crossing} vs {grid}");
}

#[test]
fn the_default_resolves_to_a_method_that_meets_it_on_the_pilots() {
    let mut rs = lens("");
    assert_eq!(
        rs.settings.step,
        StepSpec::Auto(grin_scene::DEFAULT_AUTO_ACCURACY)
    );
    let c = resolve_scene::<f64>(&mut rs).expect("resolved");
    assert!(c.met && c.chosen.error <= PILOT_TARGET * c.asked, "{c:?}");
    assert!(c.pilot_rays >= MIN_CAMERA_PILOTS, "{}", c.pilot_rays);
    // Both places the backends read agree with the choice.
    let m = rs.medium.as_ref().expect("medium");
    assert_eq!(m.trace, c.settings);
    assert_eq!(rs.settings.step, c.settings.step);
    assert_eq!(rs.settings.integrator, Some(c.settings.integrator));
    // The cheapest candidate that met the target was chosen.
    let cheaper_met = c
        .tried
        .iter()
        .filter(|t| t.error <= PILOT_TARGET * c.asked)
        .any(|t| t.cost_per_ray < c.chosen.cost_per_ray);
    assert!(!cheaper_met, "{:?}", c.tried);
}

#[test]
fn a_named_integrator_is_kept_and_zero_pilots_leave_error_control() {
    let mut rs = lens("integrator = \"rk4\"\n");
    let c = resolve_scene::<f64>(&mut rs).expect("resolved");
    assert_eq!(c.settings.integrator, IntegratorKind::Rk4);
    let mut rs = lens("pilot_rays = 0\n");
    assert!(resolve_scene::<f64>(&mut rs).is_none());
    assert_eq!(
        rs.settings.step,
        StepSpec::Auto(grin_scene::DEFAULT_AUTO_ACCURACY)
    );
    // Another policy is not touched.
    let mut rs = lens("step = { fixed = 0.01 }\n");
    assert!(resolve_scene::<f64>(&mut rs).is_none());
}

/// A ray table prices the methods it traces in packets at what they cost there: on
/// the GRIN rod at 1e-6 rad it takes one of them, where the one-ray price (a
/// render's) takes another method; both meet the request on their pilots, and each
/// is the cheapest that did by its own price.
#[test]
fn a_ray_table_prices_packet_methods_at_their_cost_in_packets() {
    let rod = grin_field::expr::ExprField::benchmark_rod();
    let pilots: Vec<(DVec3, DVec3)> = (0..64)
        .map(|i| {
            let (x, y) = (
                -1.5 + 3.0 * (i % 8) as f64 / 7.0,
                -1.5 + 3.0 * (i / 8) as f64 / 7.0,
            );
            (DVec3::new(x, y, -1.0), DVec3::new(0.0, 0.01 * y, 1.0))
        })
        .collect();
    let settings = TraceSettings {
        integrator: IntegratorKind::Adaptive,
        step: StepSpec::Auto(1e-6),
        max_steps: grin_scene::DEFAULT_MAX_STEPS,
        exit: grin_scene::ExitMethod::Hermite,
        macro_cells: true,
        accuracy: 1e-6,
        estimate_limit: 1e-6,
        opl_control: false,
    };
    let table = choose_for_table::<f64>(&rod, &settings, true, &pilots).expect("table");
    let render = choose::<f64>(&rod, &settings, true, &pilots).expect("render");
    for c in [&table, &render] {
        assert!(c.met && c.chosen.error <= PILOT_TARGET * c.asked, "{c:?}");
        let cheaper_met = c
            .tried
            .iter()
            .filter(|t| t.error <= PILOT_TARGET * c.asked)
            .any(|t| t.cost_per_ray < c.chosen.cost_per_ray);
        assert!(!cheaper_met, "{:?}", c.tried);
    }
    // Every candidate the table tried is priced as the table traces it: RK4 at
    // fixed steps and dopri (fixed or error-controlled) in packets, the rest one ray
    // at a time.
    for t in &table.tried {
        let packets = match (t.integrator, t.fixed_step) {
            ("rk4", Some(_)) => PACKET_EVAL_COST,
            ("dopri", _) => PACKET_EVAL_COST_DOPRI,
            _ => 1.0,
        };
        assert_eq!(t.cost_per_ray, packets * t.evals_per_ray, "{t:?}");
    }
    assert!(
        table
            .tried
            .iter()
            .any(|t| t.integrator == "rk4" && t.fixed_step.is_some())
            && table.tried.iter().any(|t| t.integrator == "dopri"),
        "{:?}",
        table.tried
    );
    // The table's choice runs in packets, and says so.
    assert!(crate::packet::packets_apply(&table.settings));
    let c = table.chosen;
    assert!(c.cost_per_ray < c.evals_per_ray, "{c:?}");
    assert!(
        table.describe().contains("in ray packets"),
        "{}",
        table.describe()
    );
    // One ray at a time every candidate costs its evaluations, and the choice is
    // another method.
    assert!(
        render
            .tried
            .iter()
            .all(|t| t.cost_per_ray == t.evals_per_ray)
    );
    assert_ne!(
        (render.settings.integrator, render.settings.step),
        (table.settings.integrator, table.settings.step),
        "{} / {}",
        render.describe(),
        table.describe()
    );
    // The f32 tracer (no packets) prices every candidate at its evaluations.
    let f32_table = choose_for_table::<f32>(&rod, &settings, true, &pilots);
    if let Some(c) = f32_table {
        assert!(c.tried.iter().all(|t| t.cost_per_ray == t.evals_per_ray));
    }
}
