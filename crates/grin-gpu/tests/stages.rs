//! The marcher's WGSL stages, one at a time, against their CPU twins (grin-trace's f32
//! path) on batches of states over the same baked field: `sample_field`, every
//! integrator's step, the step controller of every policy (including the f32 floors of
//! error control), and the step that leaves the medium (tunnelling check, Hermite and
//! bisection exit search). Whole-image tests (gpu_vs_cpu.rs) can hide a stage that is
//! wrong where few pixels go; here each stage's every output is compared.
//!
//! Where the backends' arithmetic differs. The CPU's f32 path does the integrators' vector
//! arithmetic in f32 as the kernel does, but samples the baked grid in f64 (rounded to
//! f32) and runs the controller's scalars (ds, tolerance, error ratio) and the exit
//! search's parameter in f64. So states agree to a few f32 ulps, not bit for bit; the
//! tolerances below are ~10x the worst difference measured on lavapipe, and far below
//! what a changed constant, floor or coefficient does (docs/architecture.md, "Twins and
//! what keeps them equal", lists the one-line changes shown to fail).
//!
//! One concept, one file: a test per WGSL stage beside its CPU twin's call sequence.

#![allow(clippy::unwrap_used)]

mod harness;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::Vec3;
use grin_field::baked::{BakedField, Interp, Storage, Voxels};
use grin_field::{FieldSample, IndexField, Real};
use grin_gpu::stages::{
    self, IntegrateIn, RayIn, SampleIn, SceneIn, Stage, SurfaceIn, TakeIn, TakeOut, run_stage,
};
use grin_render::scene::RenderScene;
use grin_render::settings::TraceSettings;
use grin_scene::{ExitMethod, IntegratorKind, Scene, StepSpec, load_scene};
use grin_trace::boundary::exit_tolerance;
use grin_trace::integrate::{self, RayState};
use grin_trace::step::StepController;
use grin_trace::trace::{excursion_step, exit_medium};

/// |n| agreement of a field sample (n ~ 1.4: a few f32 ulps).
const SAMPLE_N_TOL: f32 = 2e-6;
/// |grad n| agreement, relative to 1 + |grad n|.
const SAMPLE_GRAD_TOL: f32 = 2e-5;
/// End-state agreement (|r|, |T| ~ 1 in these scenes).
const STATE_TOL: f32 = 1e-5;
/// Relative agreement of step lengths (h).
const LENGTH_REL_TOL: f32 = 1e-3;
/// Relative agreement of the controller's next step: it is 0.9 (tol / err)^(1/p), and
/// an error estimate of ~1e-7 made from f32 states is partly rounding (measured worst
/// 3.6e-2, dopri at auto = 1e-4); SAFETY 0.8 instead of 0.9 moves it by 11%.
const NEXT_DS_REL_TOL: f32 = 0.06;
/// Error-controlled steps whose accept decision may flip between the backends (an
/// error within rounding of the tolerance): at most this fraction of a batch. Measured:
/// 6 of 256 (dopri at tolerance 1e-6, the exit stage) since the Dormand-Prince stages
/// are written out without loops (for lavapipe's loop limit), which lets the shader
/// compiler fuse their multiply-adds where the CPU twin rounds each; 5 before.
const FLIP_FRACTION: f64 = 0.03;
/// Exits one Newton re-step apart, at most this fraction of a batch: the refinement
/// stops when |distance| <= 4 ulps of the coordinates, and the backends' f32 cubic roots
/// and Newton updates (f32 on the GPU, f64 on the CPU) land on either side of that in
/// a few states (measured 7 of 256, Luneburg sharma).
const NEWTON_FLIP_FRACTION: f64 = 0.06;
/// States per batch.
const BATCH: usize = 256;
/// Bake resolution of the stage tests' grids.
const RESOLUTION: usize = 32;

fn scene_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../data/scenes/{name}.toml"))
}

/// A scene with its medium marched by `integrator` / `step` / `exit` through a bake of
/// its field (trilinear or tricubic), as the GPU and the CPU twin both see it.
struct Setup {
    scene: RenderScene,
    baked: Arc<BakedField>,
    trace: TraceSettings,
}

fn setup(
    name: &str,
    integrator: IntegratorKind,
    step: StepSpec,
    exit: ExitMethod,
    interp: Interp,
) -> Setup {
    setup_file(&scene_path(name), integrator, step, exit, interp)
}

fn setup_file(
    path: &Path,
    integrator: IntegratorKind,
    step: StepSpec,
    exit: ExitMethod,
    interp: Interp,
) -> Setup {
    let mut scene: Scene = load_scene(path).unwrap();
    scene.render.integrator = Some(integrator);
    scene.render.step = step;
    scene.render.exit = exit;
    let dir = path.parent().unwrap();
    let baked = harness::baked(&scene, dir, RESOLUTION).unwrap();
    let baked = Arc::new(Arc::try_unwrap(baked).unwrap().with_interp(interp));
    let rs =
        RenderScene::new(&scene, dir, Some(Arc::clone(&baked) as Arc<dyn IndexField>)).unwrap();
    let trace = rs.medium.as_ref().unwrap().trace;
    Setup {
        scene: rs,
        baked,
        trace,
    }
}

/// [`setup`] of scene text (sharma, fixed 0.05, Hermite exit, trilinear), read from a
/// temporary file named by `tag`.
fn setup_text(tag: &str, text: &str) -> Setup {
    let path = std::env::temp_dir().join(format!("grin-stages-{tag}-{}.toml", std::process::id()));
    std::fs::write(&path, text).unwrap();
    let s = setup_file(
        &path,
        IntegratorKind::Sharma,
        StepSpec::Fixed(0.05),
        ExitMethod::Hermite,
        Interp::Trilinear,
    );
    std::fs::remove_file(&path).ok();
    s
}

/// The CPU twin's controller for `s`, started at the kernel's `ds_adapt` (0: its first).
fn controller(s: &Setup, ds_adapt: f32) -> StepController {
    let ctrl = StepController::new(s.trace.step, s.trace.integrator, s.baked.as_ref());
    if ds_adapt > 0.0 {
        ctrl.with_current_ds(f64::from(ds_adapt))
    } else {
        ctrl
    }
}

/// [`states`]' maker of the controlled stages' input: the controller starts at the
/// cycled value.
fn take_in(r: Vec3, t: Vec3, _: f32, ds_adapt: f32) -> TakeIn {
    TakeIn::new(r.to_array(), t.to_array(), ds_adapt)
}

/// The tests' one deterministic generator (xorshift64*; grin-testkit's `rng`, included
/// by path: that crate depends on this one).
#[path = "../../grin-testkit/src/rng.rs"]
#[allow(dead_code)]
mod rng;
use rng::Rng;

/// A random unit vector (by rejection from the cube).
fn unit(rng: &mut Rng) -> Vec3 {
    loop {
        let v = Vec3::new(
            rng.range_f32(-1.0, 1.0),
            rng.range_f32(-1.0, 1.0),
            rng.range_f32(-1.0, 1.0),
        );
        let l = v.length();
        if l > 0.1 && l <= 1.0 {
            return v / l;
        }
    }
}

/// States inside the medium: position in the bounds shrunk by `inner..outer` of the
/// way from the centre to the surface, T = n(r) times a unit direction (bent outward by
/// `outward` in [0, 1]), each made a stage's input by `make` (r, T, a number drawn from
/// the range `drawn`, the next of `cycled`).
#[allow(clippy::too_many_arguments)]
fn states<I>(
    setup: &Setup,
    seed: u64,
    inner: f32,
    outer: f32,
    outward: f32,
    drawn: (f32, f32),
    cycled: &[f32],
    make: impl Fn(Vec3, Vec3, f32, f32) -> I,
) -> Vec<I> {
    let field = setup.baked.as_ref();
    let bounds = field.bounds();
    let (center, half) = match bounds {
        grin_field::Bounds::Sphere { center, radius } => {
            (center.as_vec3(), Vec3::splat(radius as f32))
        }
        grin_field::Bounds::Box { min, max } => {
            (((min + max) * 0.5).as_vec3(), ((max - min) * 0.5).as_vec3())
        }
    };
    let mut rng = Rng(seed);
    (0..BATCH)
        .map(|i| {
            let sphere = matches!(bounds, grin_field::Bounds::Sphere { .. });
            let u = unit(&mut rng);
            let f = rng.range_f32(inner, outer);
            let offset = if sphere {
                u * f
            } else {
                // A point of the box shell at fraction f: one axis pushed to f.
                let mut v = Vec3::new(
                    rng.range_f32(-outer, outer),
                    rng.range_f32(-outer, outer),
                    rng.range_f32(-outer, outer),
                );
                let axis = i % 3;
                v[axis] = f * u[axis].signum();
                v
            };
            let r = center + offset * half;
            let out = if sphere {
                u
            } else {
                let mut a = Vec3::ZERO;
                a[i % 3] = u[i % 3].signum();
                a
            };
            let d = (unit(&mut rng) * (1.0 - outward) + out * outward).normalize();
            let n = field.sample_f32(r).n;
            let x = rng.range_f32(drawn.0, drawn.1);
            make(r, d * n, x, cycled[i % cycled.len()])
        })
        .collect()
}

fn gpu<S: Stage>(setup: &Setup, input: &[S::In]) -> Option<Vec<S::Out>> {
    let ctx = harness::context(&format!("stage {}", S::ENTRY_POINT))?;
    Some(run_stage::<S>(&ctx, &setup.scene, setup.baked.as_ref(), input).expect("the stage runs"))
}

fn v(a: [f32; 3]) -> Vec3 {
    Vec3::from_array(a)
}

fn sample(field: &dyn IndexField, r: Vec3) -> FieldSample<f32> {
    f32::sample_field(field, r)
}

/// `d <= tol`, false for NaN (a NaN output is a difference).
fn within(d: f32, tol: f32) -> bool {
    d <= tol
}

/// Differences found, one line each, with the worst of each kind for the report.
#[derive(Default)]
struct Report {
    problems: Vec<String>,
    worst_state: f32,
    worst_len: f32,
}

impl Report {
    fn state(&mut self, i: usize, what: &str, gpu: Vec3, cpu: Vec3) {
        let d = (gpu - cpu).abs().max_element();
        self.worst_state = self.worst_state.max(d);
        if !within(d, STATE_TOL) {
            self.problems.push(format!(
                "state {i}: {what} GPU {gpu} vs CPU {cpu} (|d| {d:.2e})"
            ));
        }
    }
    fn length(&mut self, i: usize, what: &str, gpu: f32, cpu: f32) {
        self.length_within(i, what, gpu, cpu, LENGTH_REL_TOL);
    }
    fn length_within(&mut self, i: usize, what: &str, gpu: f32, cpu: f32, tol: f32) {
        let d = (gpu - cpu).abs() / cpu.abs().max(1e-30);
        self.worst_len = self.worst_len.max(d);
        if !within(d, tol) {
            self.problems.push(format!(
                "state {i}: {what} GPU {gpu:e} vs CPU {cpu:e} (rel {d:.2e})"
            ));
        }
    }
    fn count(&mut self, i: usize, what: &str, gpu: u32, cpu: u32) {
        if gpu != cpu {
            self.problems
                .push(format!("state {i}: {what} GPU {gpu} vs CPU {cpu}"));
        }
    }
    /// No difference, except accept-decision flips in at most FLIP_FRACTION of the
    /// states when `flips` is set.
    fn check(self, label: &str, flips: bool) {
        let allowed = if flips {
            (FLIP_FRACTION * BATCH as f64) as usize
        } else {
            0
        };
        let differing: std::collections::BTreeSet<&str> = self
            .problems
            .iter()
            .map(|p| p.split(':').next().unwrap_or(""))
            .collect();
        eprintln!(
            "{label}: worst |state| {:.2e}, worst rel length {:.2e}, {} states differ",
            self.worst_state,
            self.worst_len,
            differing.len()
        );
        assert!(
            differing.len() <= allowed,
            "{label}: {} of {BATCH} states differ between the WGSL stage and its CPU twin (allowed {allowed}):\n{}",
            differing.len(),
            self.problems[..self.problems.len().min(12)].join("\n")
        );
    }
}

#[test]
fn sample_field_matches_the_cpu_trilinear_and_tricubic_grids() {
    for (interp, storage) in [
        (Interp::Trilinear, Storage::F32),
        (Interp::Trilinear, Storage::I16),
        (Interp::Tricubic, Storage::F32),
    ] {
        let mut s = setup(
            "luneburg",
            IntegratorKind::Sharma,
            StepSpec::Fixed(0.05),
            ExitMethod::Hermite,
            interp,
        );
        if storage == Storage::I16 {
            // The same grid quantized (grin bake's i16 storage): rgba16snorm on a device
            // that has it, scaled in the shader; the CPU blends the integers.
            let b = s.baked.as_ref();
            let quantized = BakedField::new(
                *b.geometry(),
                Voxels::quantize(&b.voxels().to_f32()),
                interp,
                b.outside(),
                b.bounds(),
                b.ambient_index(),
                b.provenance().clone(),
            )
            .unwrap();
            s.baked = Arc::new(quantized);
            if let Some(ctx) = harness::context("stage sample i16") {
                let mut params = <grin_gpu::gpu_data::FrameParams as bytemuck::Zeroable>::zeroed();
                let up = grin_gpu::field::upload_field(&ctx, &s.baked, &mut params).unwrap();
                let snorm = params.flags & grin_gpu::gpu_data::FLAG_FIELD_SNORM != 0;
                assert_eq!(snorm, ctx.has_snorm16());
                let texel = if snorm { 8 } else { 16 };
                assert!(
                    up.bytes >= s.baked.voxels().len() as u64 * texel,
                    "{} bytes",
                    up.bytes
                );
            }
        }
        // Points in and just beyond the grid (beyond it the field is clamped or ambient).
        let input = states(&s, 7, 0.0, 1.1, 0.0, (0.0, 0.0), &[0.0], |r, _, _, _| {
            SampleIn::new(r.to_array())
        });
        let Some(out) = gpu::<stages::Sample>(&s, &input) else {
            return;
        };
        let field = s.baked.as_ref();
        let mut problems = Vec::new();
        let (mut worst_n, mut worst_g) = (0.0f32, 0.0f32);
        for (i, (inp, o)) in input.iter().zip(&out).enumerate() {
            let c = sample(field, v(inp.r));
            let dn = (o.n - c.n).abs();
            let dg = (v(o.grad_n) - c.grad_n).abs().max_element() / (1.0 + c.grad_n.length());
            worst_n = worst_n.max(dn);
            worst_g = worst_g.max(dg);
            if !(within(dn, SAMPLE_N_TOL) && within(dg, SAMPLE_GRAD_TOL)) {
                problems.push(format!(
                    "point {i} {:?}: n GPU {} CPU {}, grad n GPU {:?} CPU {}",
                    inp.r, o.n, c.n, o.grad_n, c.grad_n
                ));
            }
        }
        eprintln!(
            "sample {interp:?} {storage:?}: worst |n| {worst_n:.2e}, worst rel grad {worst_g:.2e}"
        );
        assert!(
            problems.is_empty(),
            "sample_field {interp:?} {storage:?}: {} of {BATCH} points differ:\n{}",
            problems.len(),
            problems[..problems.len().min(12)].join("\n")
        );
    }
}

#[test]
fn every_integrator_step_matches_its_cpu_twin() {
    for kind in [
        IntegratorKind::Euler,
        IntegratorKind::SymplecticEuler,
        IntegratorKind::Verlet,
        IntegratorKind::Sharma,
        IntegratorKind::Rk4,
        IntegratorKind::Adaptive,
    ] {
        let s = setup(
            "luneburg",
            kind,
            StepSpec::Fixed(0.05),
            ExitMethod::Hermite,
            Interp::Trilinear,
        );
        // Steps of 0.02..0.25 R from points well inside.
        let input = states(&s, 11, 0.0, 0.7, 0.0, (0.02, 0.25), &[0.0], |r, t, h, _| {
            IntegrateIn::new(r.to_array(), t.to_array(), h)
        });
        let Some(out) = gpu::<stages::Integrate>(&s, &input) else {
            return;
        };
        let field = s.baked.as_ref();
        let mut rep = Report::default();
        for (i, (inp, o)) in input.iter().zip(&out).enumerate() {
            let st = RayState {
                r: v(inp.r),
                t: v(inp.t),
            };
            let s0 = sample(field, st.r);
            let c = integrate::step(kind, field, st, s0.n_grad_n(), inp.h);
            rep.state(i, "r", v(o.r), c.state.r);
            rep.state(i, "T", v(o.t), c.state.t);
            rep.count(i, "evals", o.evals, c.evals);
            if let Some((er, et)) = c.error {
                rep.state(i, "e_r", v(o.err_r), er);
                rep.state(i, "e_T", v(o.err_t), et);
            }
            if let Some(end) = c.end {
                rep.length(i, "end n", o.end_n, end.n);
            }
        }
        rep.check(&format!("integrate {kind:?}"), false);
    }
}

/// Median ratio GPU / CPU of the controller's next step allowed where the tolerance is
/// below f32 roundoff: there the error estimate is rounding noise (each state's next
/// step differs by up to ~10% between the backends) and only the floor sets the steps'
/// scale; a floor of 4 units of roundoff instead of 2 moves the median by 2^(1/5) - 1
/// = 15%.
const FLOOR_MEDIAN_TOL: f32 = 0.03;

/// One controlled step on both backends from each state, the controllers started at
/// the state's `ds_adapt`. `floor`: the tolerance is below roundoff (compared by the
/// median of the next steps, and states where both backends took the same step).
fn compare_take(
    label: &str,
    s: &Setup,
    input: &[TakeIn],
    out: &[TakeOut],
    flips: bool,
    floor: bool,
) {
    let field = s.baked.as_ref();
    let mut rep = Report::default();
    let mut ratios = Vec::new();
    for (i, (inp, o)) in input.iter().zip(out).enumerate() {
        let mut ctrl = controller(s, inp.ds_adapt);
        let st = RayState {
            r: v(inp.r),
            t: v(inp.t),
        };
        let s0 = sample(field, st.r);
        let c = ctrl.take::<f32>(field, st, &s0);
        if floor {
            ratios.push(o.ds_next / ctrl.current_ds() as f32);
            if o.h != c.h {
                continue;
            }
        }
        rep.length(i, "h", o.h, c.h);
        rep.state(i, "r", v(o.r), c.step.state.r);
        rep.state(i, "T", v(o.t), c.step.state.t);
        if !floor {
            rep.count(i, "evals", o.evals, c.evals);
        }
        if !floor && matches!(s.trace.step, StepSpec::Adaptive { .. } | StepSpec::Auto(_)) {
            rep.length_within(
                i,
                "next ds",
                o.ds_next,
                ctrl.current_ds() as f32,
                NEXT_DS_REL_TOL,
            );
        }
    }
    if floor {
        ratios.sort_by(f32::total_cmp);
        let median = ratios[ratios.len() / 2];
        eprintln!("{label}: median next-step ratio GPU/CPU {median:.4}");
        assert!(
            (median - 1.0).abs() <= FLOOR_MEDIAN_TOL,
            "{label}: median next-step ratio GPU/CPU {median} (a floor differs?)"
        );
    }
    rep.check(label, flips);
}

#[test]
fn the_step_controller_of_every_policy_matches_its_cpu_twin() {
    let cases = [
        // (integrator, policy, controller starts)
        (IntegratorKind::Sharma, StepSpec::Fixed(0.08), vec![0.0]),
        (
            IntegratorKind::Rk4,
            StepSpec::Heuristic {
                min: 0.01,
                max: 0.2,
                amplitude: None,
            },
            vec![0.0],
        ),
        // The embedded pair and step doubling, from several controller states.
        (
            IntegratorKind::Adaptive,
            StepSpec::Adaptive {
                tolerance: 1e-5,
                initial: None,
            },
            vec![0.0, 0.003, 0.05, 0.3],
        ),
        (
            IntegratorKind::Rk4,
            StepSpec::Adaptive {
                tolerance: 1e-6,
                initial: Some(0.02),
            },
            vec![0.0, 0.003, 0.05, 0.3],
        ),
        // Below f32 roundoff: the tolerance floor and the smallest step decide.
        (
            IntegratorKind::Adaptive,
            StepSpec::Adaptive {
                tolerance: 1e-10,
                initial: None,
            },
            vec![0.0, 1e-4, 0.01],
        ),
        (
            IntegratorKind::Sharma,
            StepSpec::Adaptive {
                tolerance: 1e-12,
                initial: None,
            },
            vec![0.0, 1e-4, 0.01],
        ),
        // Error per unit length (`auto`).
        (
            IntegratorKind::Verlet,
            StepSpec::Auto(1e-3),
            vec![0.0, 0.01, 0.1],
        ),
        (
            IntegratorKind::Adaptive,
            StepSpec::Auto(1e-4),
            vec![0.0, 0.01, 0.1],
        ),
        (
            IntegratorKind::Adaptive,
            StepSpec::Auto(1e-7),
            vec![0.0, 0.01, 0.1],
        ),
    ];
    for (kind, step, starts) in cases {
        let s = setup(
            "luneburg",
            kind,
            step,
            ExitMethod::Hermite,
            Interp::Trilinear,
        );
        let input = states(&s, 13, 0.0, 0.9, 0.0, (0.0, 0.0), &starts, take_in);
        let Some(out) = gpu::<stages::Take>(&s, &input) else {
            return;
        };
        let flips = !matches!(step, StepSpec::Fixed(_) | StepSpec::Heuristic { .. });
        // Per-step tolerances (auto: per unit length, times steps <= 0.25 R) below the
        // f32 floor of 2 roundoff units times R = 2.4e-7.
        let floor = match step {
            StepSpec::Adaptive { tolerance, .. } => tolerance < 1e-8,
            StepSpec::Auto(a) => grin_scene::AUTO_TOL_PER_RAD * a * 0.25 < 2.4e-7,
            _ => false,
        };
        compare_take(
            &format!("take {kind:?} {step:?}"),
            &s,
            &input,
            &out,
            flips,
            floor,
        );
    }
}

#[test]
fn the_step_that_leaves_the_medium_matches_its_cpu_twin() {
    let cases = [
        (
            "luneburg",
            IntegratorKind::Sharma,
            StepSpec::Fixed(0.1),
            ExitMethod::Hermite,
        ),
        (
            "luneburg",
            IntegratorKind::Adaptive,
            StepSpec::Adaptive {
                tolerance: 1e-6,
                initial: None,
            },
            ExitMethod::Hermite,
        ),
        (
            "luneburg",
            IntegratorKind::Rk4,
            StepSpec::Fixed(0.1),
            ExitMethod::Bisection,
        ),
        (
            "grin-rod",
            IntegratorKind::Rk4,
            StepSpec::Fixed(0.1),
            ExitMethod::Hermite,
        ),
    ];
    for (name, kind, step, exit) in cases {
        let s = setup(name, kind, step, exit, Interp::Trilinear);
        // Near the surface, heading out or grazing it.
        let input = states(&s, 17, 0.9, 0.999, 0.5, (0.0, 0.0), &[0.1, 0.25], take_in);
        let Some(out) = gpu::<stages::Leave>(&s, &input) else {
            return;
        };
        let field = s.baked.as_ref();
        let bounds = field.bounds();
        let mut rep = Report::default();
        let mut codes = [0usize; 3];
        let mut newton_flips = 0;
        for (i, (inp, o)) in input.iter().zip(&out).enumerate() {
            let mut ctrl = controller(&s, inp.ds_adapt);
            let st = RayState {
                r: v(inp.r),
                t: v(inp.t),
            };
            let s0 = sample(field, st.r);
            let mut taken = ctrl.take::<f32>(field, st, &s0);
            let mut evals = taken.evals;
            let mut code = 0;
            if bounds.signed_distance(taken.step.state.r.as_dvec3()) > 0.0 {
                code = 1;
            } else if let Some(cut) = excursion_step(field, &s.trace, &bounds, st, &s0, &taken) {
                evals += cut.evals;
                taken = cut;
                code = 2;
            }
            let (mut state, mut h) = (taken.step.state, taken.h);
            if code != 0 {
                let (es, eh, ee, _) = exit_medium(
                    field,
                    &s.trace,
                    &bounds,
                    st,
                    &s0,
                    &taken,
                    exit_tolerance::<f32>(&bounds),
                );
                state = es;
                h = eh;
                evals += ee;
            }
            codes[code as usize] += 1;
            rep.count(i, "outcome", o.outcome, code);
            rep.state(i, "r", v(o.r), state.r);
            rep.state(i, "T", v(o.t), state.t);
            rep.length(i, "h", o.h, h);
            // The Newton refinement stops when |distance| <= the f32 tolerance, which
            // the GPU (f32 distance) and the CPU (f64 distance of the f32 point) may
            // see one re-step apart: a few states may differ by one step's evaluations.
            let per_step = integrate::step(kind, field, st, s0.n_grad_n(), 1e-3).evals;
            if exit == ExitMethod::Hermite && o.evals != evals {
                if o.evals.abs_diff(evals) == per_step {
                    newton_flips += 1;
                } else {
                    rep.count(i, "evals", o.evals, evals);
                }
            }
        }
        let label =
            format!("leave {name} {kind:?} {step:?} {exit:?} (inside/out/tunnelled {codes:?})");
        assert!(
            codes[1] >= BATCH / 4,
            "{label}: too few steps leave to test the exit"
        );
        eprintln!("{label}: {newton_flips} exits one Newton re-step apart");
        assert!(
            newton_flips as f64 <= NEWTON_FLIP_FRACTION * BATCH as f64,
            "{label}: {newton_flips} of {BATCH} exits differ by one Newton re-step"
        );
        rep.check(&label, !matches!(step, StepSpec::Fixed(_)));
    }
}

/// Straight flights through homogeneous macro cells (the paper's "infinite step"): the
/// kernel's macro-cell walk against BakedField::homogeneous_span, from points all over
/// the plume scene's box (cropped grid, ambient outside it) in every direction.
#[test]
fn straight_flights_match_the_cpu_macro_cell_walk() {
    // Two narrow plumes in opposite corners of the box: the grid spans the box, and the
    // space between them is homogeneous macro cells.
    let text = std::fs::read_to_string(scene_path("plume")).unwrap();
    let start = text.find("field = { kind = \"plume\"").unwrap();
    let end = start + text[start..].find("] }").unwrap() + 3;
    let text = format!(
        "{}field = {{ kind = \"plume\", plumes = [{{ a = 6.0e-3, center = [-2.5, 0.4, 1.6], s = 0.15 }}, {{ a = 5.0e-3, center = [2.5, 0.9, 6.4], s = 0.15 }}] }}{}",
        &text[..start],
        &text[end..]
    );
    let s = setup_text("flights", &text);
    // Half from all over the bounds (most fly to the cropped grid), half inside the
    // grid's box (macro-cell walks).
    let mut input = states(&s, 19, 0.0, 0.999, 0.0, (0.0, 0.0), &[0.0], |r, t, _, _| {
        RayIn::new(r.to_array(), t.to_array())
    });
    let (lo, hi) = s.baked.geometry().world_box();
    let mut rng = Rng(23);
    for inp in input.iter_mut().skip(BATCH / 2) {
        let f = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        inp.r = (lo.as_vec3() + (hi - lo).as_vec3() * f).to_array();
    }
    let Some(out) = gpu::<stages::Flight>(&s, &input) else {
        return;
    };
    let field = s.baked.as_ref();
    let mut problems = Vec::new();
    let (mut flights, mut walks, mut worst) = (0, 0, 0.0f64);
    for (i, (inp, o)) in input.iter().zip(&out).enumerate() {
        let p = v(inp.r).as_dvec3();
        let dir = v(inp.t).normalize().as_dvec3();
        let cpu = field.homogeneous_span(p, dir);
        let gpu = (o.span > 0.0).then_some(f64::from(o.span));
        if o.may_fly == 0 && cpu.is_some() {
            problems.push(format!(
                "state {i}: may_fly false but the CPU flies {cpu:?}"
            ));
        }
        match (gpu, cpu) {
            (None, None) => {}
            (Some(g), Some(c)) => {
                flights += 1;
                if i >= BATCH / 2 {
                    walks += 1;
                }
                let d = (g - c).abs() / c.max(1e-3);
                worst = worst.max(d);
                if d > 1e-3 {
                    problems.push(format!("state {i}: span GPU {g} vs CPU {c}"));
                }
            }
            _ => problems.push(format!("state {i}: span GPU {gpu:?} vs CPU {cpu:?}")),
        }
    }
    eprintln!(
        "flight: {flights} of {BATCH} states fly on both ({walks} inside the grid), worst rel span {worst:.2e}, {} differ",
        problems.len()
    );
    assert!(
        flights >= BATCH / 4 && walks >= BATCH / 16,
        "too few flights to test: {flights}, {walks} inside the grid"
    );
    assert!(
        problems.len() as f64 <= FLIP_FRACTION * BATCH as f64,
        "straight flights: {} of {BATCH} states differ:\n{}",
        problems.len(),
        problems[..problems.len().min(12)].join("\n")
    );
}

/// A sparse bake (grin_field::sparse) on the GPU: `sample_field` reads its brick table
/// (the macro-cell texture) and voxels (one linear texture, f32 or rgba16snorm) and the
/// straight-flight walk crosses its empty bricks, as SparseField does on the CPU; points
/// inside active bricks of every level, and all over the box; f32 and i16 voxels,
/// trilinear and tricubic Catmull-Rom (bricks with an apron).
#[test]
fn sparse_bakes_sample_and_fly_as_their_cpu_twin() {
    use grin_field::baked::{Interp, Storage};
    for (interp, of_n) in [
        (Interp::Trilinear, false),
        (Interp::Tricubic, false),
        (Interp::Tricubic, true),
    ] {
        for storage in [Storage::F32, Storage::I16] {
            sparse_twin(storage, interp, of_n);
        }
    }
}

/// The plume scene with two plumes in it, and its directory.
fn two_plumes() -> (Scene, PathBuf) {
    let text = std::fs::read_to_string(scene_path("plume")).unwrap();
    let start = text.find("field = { kind = \"plume\"").unwrap();
    let end = start + text[start..].find("] }").unwrap() + 3;
    let text = format!(
        "{}field = {{ kind = \"plume\", plumes = [{{ a = 6.0e-3, center = [-2.5, 0.4, 1.6], s = 0.15 }}, {{ a = 5.0e-3, center = [2.5, 0.9, 6.4], s = 0.25 }}] }}{}",
        &text[..start],
        &text[end..]
    );
    // A file of its own per call: the tests that read it run at once.
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let path = std::env::temp_dir().join(format!(
        "grin-stages-sparse-{}-{call}.toml",
        std::process::id()
    ));
    std::fs::write(&path, text).unwrap();
    let scene: Scene = load_scene(&path).unwrap();
    std::fs::remove_file(&path).ok();
    (scene, path.parent().unwrap().to_owned())
}

/// A sequence's sparse frames share their compiled pipelines whether or not a frame has
/// an empty brick: the upload keeps the macro-cell flag (a pipeline constant) either way.
#[test]
fn sparse_bakes_with_and_without_empty_bricks_keep_one_pipeline() {
    use grin_field::sparse::bake::{SparseOptions, bake_sparse};
    let (scene, dir) = two_plumes();
    let source = grin_field::build_field(scene.medium.as_ref().unwrap(), &dir).unwrap();
    let Some(ctx) = harness::context("sparse macro-cell flag") else {
        return;
    };
    let mut flags = Vec::new();
    for top_bricks in [1, 24] {
        // A loose budget: one brick's finest cells meet it.
        let opts = SparseOptions {
            top_bricks: Some(top_bricks),
            error_budget: 0.05,
            ..Default::default()
        };
        let (sparse, _) = bake_sparse(source.as_ref(), &opts, &|_, _, _| {}).unwrap();
        let empty = sparse.table().contains(&grin_field::sparse::EMPTY);
        // One brick holds the plumes; 24^3 leave most of the box empty.
        assert_eq!(empty, top_bricks > 1, "{top_bricks} bricks a side");
        let mut params = <grin_gpu::gpu_data::FrameParams as bytemuck::Zeroable>::zeroed();
        params.flags = grin_gpu::gpu_data::FLAG_MACRO_CELLS;
        grin_gpu::field::upload_sparse(&ctx, &sparse, &mut params).unwrap();
        flags.push(params.flags);
    }
    assert_eq!(
        flags[0], flags[1],
        "flags {:#x} and {:#x}",
        flags[0], flags[1]
    );
    assert_ne!(flags[0] & grin_gpu::gpu_data::FLAG_MACRO_CELLS, 0);
}

/// `of_n`: the Catmull-Rom field's gradient is the derivative of its delta_n (what a bake
/// on a VDB grid's own lattice samples), forced on this bake of an analytic plume.
fn sparse_twin(storage: grin_field::baked::Storage, interp: grin_field::baked::Interp, of_n: bool) {
    use grin_field::sparse::bake::{SparseOptions, bake_sparse};
    let (scene, dir) = two_plumes();
    let dir = dir.as_path();
    let source = grin_field::build_field(scene.medium.as_ref().unwrap(), dir).unwrap();
    let opts = SparseOptions {
        top_bricks: Some(24),
        storage: Some(storage),
        interp,
        ..Default::default()
    };
    let (sparse, report) = bake_sparse(source.as_ref(), &opts, &|_, _, _| {}).unwrap();
    let levels = report.levels.iter().filter(|&&n| n > 0).count();
    // Trilinear bricks span at least 3 levels here; Catmull-Rom's coarser ones 2.
    let least = if interp == grin_field::baked::Interp::Trilinear {
        3
    } else {
        2
    };
    assert!(
        levels >= least,
        "bricks of several levels: {:?}",
        report.levels
    );
    assert_eq!(sparse.storage(), storage);
    assert_eq!(sparse.interp(), interp);
    let sparse = sparse.with_gradient_of_n(of_n).unwrap();
    let storage = format!(
        "{storage:?} {}{}",
        interp.name(),
        if of_n { " (gradient of n)" } else { "" }
    );
    let sparse = Arc::new(sparse);
    let rs = RenderScene::new(
        &scene,
        dir,
        Some(Arc::clone(&sparse) as Arc<dyn IndexField>),
    )
    .unwrap();
    let Some(ctx) = harness::context("stage sparse") else {
        return;
    };
    // i16 voxels stay 16-bit on a device with rgba16snorm (lavapipe has it): half the bytes.
    let mut params = <grin_gpu::gpu_data::FrameParams as bytemuck::Zeroable>::zeroed();
    let up = grin_gpu::field::upload_sparse(&ctx, &sparse, &mut params).unwrap();
    let snorm = params.flags & grin_gpu::gpu_data::FLAG_FIELD_SNORM != 0;
    assert_eq!(
        snorm,
        sparse.storage() == grin_field::baked::Storage::I16 && ctx.has_snorm16(),
        "{storage} voxels"
    );
    assert_eq!(
        params.flags & grin_gpu::gpu_data::FLAG_TRICUBIC != 0,
        interp == grin_field::baked::Interp::Tricubic,
        "{storage}: the tricubic flag"
    );
    assert_eq!(
        params.flags & grin_gpu::gpu_data::FLAG_GRADIENT_OF_N != 0,
        of_n,
        "{storage}: the gradient-of-n flag"
    );
    let texel = if snorm { 8 } else { 16 };
    assert!(
        up.bytes >= sparse.pool().len() as u64 * texel
            && up.bytes
                < (sparse.pool().len() as u64 + 65536) * texel + sparse.table().len() as u64 * 32,
        "{storage}: {} bytes for {} voxels",
        up.bytes,
        sparse.pool().len()
    );
    eprintln!(
        "sparse {storage}: {} bytes on the device (snorm texels: {snorm})",
        up.bytes
    );
    // Half the points inside active bricks, half anywhere in the box.
    let mut rng = Rng(31);
    let (lo, hi) = sparse.bounds().aabb();
    let top = *sparse.top();
    let points: Vec<Vec3> = (0..BATCH)
        .map(|i| {
            let f = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            if i % 2 == 0 {
                let b = sparse.bricks()[rng.below(sparse.bricks().len())];
                let (blo, _) = top.brick_box(b.at.map(|a| a as usize));
                blo.as_vec3() + f * top.edge as f32
            } else {
                lo.as_vec3() + (hi - lo).as_vec3() * f
            }
        })
        .collect();
    let input: Vec<SampleIn> = points.iter().map(|r| SampleIn::new(r.to_array())).collect();
    let out = run_stage::<stages::Sample>(&ctx, &rs, sparse.as_ref(), &input).unwrap();
    let mut problems = Vec::new();
    let (mut worst_n, mut worst_g, mut varying) = (0.0f32, 0.0f32, 0);
    for (i, (r, o)) in points.iter().zip(&out).enumerate() {
        let c = sample(sparse.as_ref(), *r);
        let dn = (o.n - c.n).abs();
        let dg = (v(o.grad_n) - c.grad_n).abs().max_element() / (1.0 + c.grad_n.length());
        worst_n = worst_n.max(dn);
        worst_g = worst_g.max(dg);
        if c.n != sparse.ambient_index() as f32 {
            varying += 1;
        }
        if !(within(dn, SAMPLE_N_TOL) && within(dg, SAMPLE_GRAD_TOL)) {
            problems.push(format!(
                "point {i} {r}: n GPU {} CPU {}, grad n GPU {:?} CPU {}",
                o.n, c.n, o.grad_n, c.grad_n
            ));
        }
    }
    eprintln!(
        "sparse {storage} sample: {varying} of {BATCH} points off ambient, worst |n| {worst_n:.2e}, worst rel grad {worst_g:.2e}"
    );
    assert!(
        (BATCH / 3..BATCH).contains(&varying),
        "points where the field varies: {varying} of {BATCH}"
    );
    assert!(
        problems.is_empty(),
        "sparse sample_field: {} of {BATCH} points differ:\n{}",
        problems.len(),
        problems[..problems.len().min(12)].join("\n")
    );
    // Straight flights from the same points in random directions.
    let dirs: Vec<Vec3> = (0..BATCH).map(|_| unit(&mut rng)).collect();
    let input: Vec<RayIn> = points
        .iter()
        .zip(&dirs)
        .map(|(r, d)| RayIn::new(r.to_array(), d.to_array()))
        .collect();
    let out = run_stage::<stages::Flight>(&ctx, &rs, sparse.as_ref(), &input).unwrap();
    let (mut flights, mut worst) = (0, 0.0f64);
    for (i, ((r, d), o)) in points.iter().zip(&dirs).zip(&out).enumerate() {
        let cpu = sparse.homogeneous_span(r.as_dvec3(), d.as_dvec3());
        let gpu = (o.span > 0.0).then_some(f64::from(o.span));
        match (gpu, cpu) {
            (None, None) => {}
            (Some(g), Some(c)) => {
                flights += 1;
                let rel = (g - c).abs() / c.max(1e-3);
                worst = worst.max(rel);
                if rel > 1e-3 {
                    problems.push(format!("state {i}: span GPU {g} vs CPU {c}"));
                }
            }
            _ => problems.push(format!("state {i}: span GPU {gpu:?} vs CPU {cpu:?}")),
        }
    }
    eprintln!(
        "sparse {storage} flights: {flights} of {BATCH} fly on both, worst rel span {worst:.2e}"
    );
    assert!(flights >= BATCH / 4, "too few flights to test: {flights}");
    assert!(
        problems.len() as f64 <= FLIP_FRACTION * BATCH as f64,
        "sparse flights: {} of {BATCH} differ:\n{}",
        problems.len(),
        problems[..problems.len().min(12)].join("\n")
    );
}

/// The medium's surface: ray-bounds intervals, signed distances and Snell + Fresnel at
/// it (sphere and box bounds), from inside and outside, into denser and thinner media
/// (total internal reflection included).
#[test]
fn the_surface_stage_matches_its_cpu_twin() {
    for name in ["luneburg", "grin-rod"] {
        let s = setup(
            name,
            IntegratorKind::Sharma,
            StepSpec::Fixed(0.05),
            ExitMethod::Hermite,
            Interp::Trilinear,
        );
        let mut input = states(
            &s,
            29,
            0.3,
            1.4,
            0.3,
            (1.0, 1.6),
            &[1.0, 1.33, 1.6],
            |r, t, n1, n2| SurfaceIn {
                r: r.to_array(),
                n1,
                t: t.to_array(),
                n2,
            },
        );
        // Ambient rays from outside aimed anywhere: many miss, many meet the bounds.
        for (i, inp) in input.iter_mut().enumerate() {
            if i % 2 == 1 {
                inp.t = (-v(inp.t)).to_array();
            }
        }
        let Some(out) = gpu::<stages::Surface>(&s, &input) else {
            return;
        };
        let bounds = s.baked.bounds();
        let mut rep = Report::default();
        let (mut met, mut tir) = (0, 0);
        for (i, (inp, o)) in input.iter().zip(&out).enumerate() {
            let p = v(inp.r).as_dvec3();
            let d = v(inp.t).normalize().as_dvec3();
            let cpu_sd = bounds.signed_distance(p) as f32;
            rep.state(
                i,
                "signed distance",
                Vec3::splat(o.signed_distance),
                Vec3::splat(cpu_sd),
            );
            match bounds.intersect(p, d) {
                Some((s_in, s_out)) => {
                    met += 1;
                    rep.count(i, "met", o.met, 1);
                    // Relative to the distance (f32 ulps of it; the slab test divides).
                    let rel = |x: f32, y: f64| Vec3::splat(x / (1.0 + y.abs() as f32));
                    let cpu = |y: f64| rel(y as f32, y);
                    rep.state(i, "s_in", rel(o.s_in, s_in), cpu(s_in));
                    rep.state(i, "s_out", rel(o.s_out, s_out), cpu(s_out));
                }
                None => rep.count(i, "met", o.met, 0),
            }
            let nrm = v(o.normal).as_dvec3();
            let n1 = f64::from(inp.n1);
            let n2 = f64::from(inp.n2);
            match grin_trace::boundary::refract(d, nrm, n1, n2) {
                grin_trace::Interface::Transmitted { dir, reflectance } => {
                    rep.count(i, "transmitted", o.transmitted, 1);
                    rep.state(i, "refracted", v(o.dir), dir.as_vec3());
                    rep.state(
                        i,
                        "reflectance",
                        Vec3::splat(o.reflectance),
                        Vec3::splat(reflectance as f32),
                    );
                }
                grin_trace::Interface::Reflected { dir } => {
                    tir += 1;
                    rep.count(i, "transmitted", o.transmitted, 0);
                    rep.state(i, "reflected", v(o.dir), dir.as_vec3());
                }
            }
        }
        assert!(
            met >= BATCH / 8 && tir >= BATCH / 32,
            "{name}: met {met}, TIR {tir}"
        );
        // A ray grazing the surface or the TIR angle may fall either side in f32.
        rep.check(&format!("surface {name} (met {met}, TIR {tir})"), true);
    }
}

/// The scene outside the medium: nearest-object intersection (sphere, plane, box; from
/// outside and inside them) and the gradient sky, against grin-render's functions.
#[test]
fn the_scene_stage_matches_its_cpu_twin() {
    let text = std::fs::read_to_string(scene_path("luneburg"))
        .unwrap()
        .replace(
            "[medium]",
            r#"[[object]]
shape = { sphere = { center = [1.2, 0.4, 0.5], radius = 0.6 } }
material = "glass"

[[object]]
shape = { box = { min = [-2.0, -1.0, -0.5], max = [-1.2, 0.2, 0.7] } }
material = "mirror"

[medium]"#,
        );
    let s = setup_text("scene", &text);
    let mut rng = Rng(31);
    let input: Vec<SceneIn> = (0..BATCH)
        .map(|i| {
            let r = Vec3::new(
                rng.range_f32(-2.5, 2.5),
                rng.range_f32(-1.5, 1.5),
                rng.range_f32(-3.0, 2.0),
            );
            // A quarter aimed near the sphere, a quarter near the box.
            let aim = match i % 4 {
                1 => Vec3::new(1.2, 0.4, 0.5),
                2 => Vec3::new(-1.6, -0.4, 0.1),
                _ => r + unit(&mut rng),
            };
            let t = ((aim - r).normalize() + unit(&mut rng) * 0.3).normalize();
            let t_min = if i % 8 == 0 { 0.0 } else { 1e-3 };
            SceneIn::new(r.to_array(), t.to_array(), t_min)
        })
        .collect();
    let Some(out) = gpu::<stages::Scene>(&s, &input) else {
        return;
    };
    let rs = &s.scene;
    let mut rep = Report::default();
    let mut hits = [0usize; 4];
    for (i, (inp, o)) in input.iter().zip(&out).enumerate() {
        let p = v(inp.r).as_dvec3();
        let d = v(inp.t).normalize().as_dvec3();
        match grin_render::primitives::intersect_scene(
            &rs.objects,
            p,
            d,
            f64::from(inp.t_min),
            f64::INFINITY,
        ) {
            Some(hit) => {
                hits[hit.object.min(3)] += 1;
                rep.count(i, "object", o.object, hit.object as u32 + 1);
                let rel = |x: f32, y: f64| Vec3::splat(x / (1.0 + y.abs() as f32));
                rep.state(
                    i,
                    "distance",
                    rel(o.distance, hit.t),
                    rel(hit.t as f32, hit.t),
                );
                rep.state(i, "normal", v(o.normal), hit.normal.as_vec3());
            }
            None => rep.count(i, "object", o.object, 0),
        }
        rep.state(i, "sky", v(o.sky), rs.sky.sky_radiance(d).as_vec3());
    }
    assert!(
        hits.iter().all(|&h| h >= 8),
        "hits per object (wall, floor, sphere, box): {hits:?}"
    );
    // A ray grazing an edge may hit or miss in f32.
    rep.check(&format!("scene (hits {hits:?})"), true);
}
