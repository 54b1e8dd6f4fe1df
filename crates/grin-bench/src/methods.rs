//! The methods a sweep runs: integrator x step policy x exit method x precision, each at
//! a list of step sizes or tolerances (relative to the case's length scale).

use grin_render::settings::TraceSettings;
use grin_scene::{ExitMethod, IntegratorKind, StepSpec};

/// How step lengths are chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, strum::IntoStaticStr)]
#[strum(serialize_all = "kebab-case")]
pub enum Policy {
    /// ds = param * scale.
    Fixed,
    /// The paper's heuristic, between param * scale / 8 and param * scale.
    Heuristic,
    /// Error control at tolerance param * scale (embedded pair for `adaptive`, step
    /// doubling for the others).
    Adaptive,
    /// Error control held to an error per unit path length for an exit-direction error
    /// of param (rad): what `step = { auto = param }` runs without pilot rays
    /// (`pilot_rays = 0`), with this integrator.
    PerLength,
    /// `step = { auto = param }` as a scene without an integrator gets it: pilot rays
    /// (the case's `pilots`) choose the integrator and step
    /// ([`grin_trace::auto`]); the method's integrator is its fallback, dopri.
    Auto,
}

impl Policy {
    pub const ALL: [Policy; 5] = [
        Policy::Fixed,
        Policy::Heuristic,
        Policy::Adaptive,
        Policy::PerLength,
        Policy::Auto,
    ];
    pub fn name(self) -> &'static str {
        self.into()
    }
}

/// Arithmetic and backend of the integration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, strum::IntoStaticStr)]
#[strum(serialize_all = "lowercase")]
pub enum Precision {
    F64,
    /// What the GPU computes (the CPU f32 twin).
    F32,
    /// The GPU itself: the render kernel's `march_medium` in f32 on the adapter
    /// ([`grin_gpu::GpuRayTracer`]), on the cases whose field is a baked grid (the only
    /// field the GPU samples). On the CPU (auto's pilots) it stands for the f32 twin.
    Gpu,
}

impl Precision {
    pub const ALL: [Precision; 3] = [Precision::F64, Precision::F32, Precision::Gpu];

    pub fn name(self) -> &'static str {
        self.into()
    }

    /// f32 arithmetic (the CPU twin or the GPU).
    pub fn is_f32(self) -> bool {
        self != Precision::F64
    }
}

/// Integrator, step policy, exit method and precision: one curve of a chart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Method {
    pub integrator: IntegratorKind,
    pub policy: Policy,
    pub exit: ExitMethod,
    pub precision: Precision,
}

/// Name of an exit method as the scene file writes it.
pub fn exit_name(exit: ExitMethod) -> &'static str {
    exit.into()
}

/// The integrator's name as charts show it (`adaptive` is the Dormand-Prince pair).
pub use grin_trace::auto::label as integrator_label;

impl Method {
    /// `rk4 fixed hermite f64`.
    pub fn label(&self) -> String {
        format!(
            "{} {} {} {}",
            self.integrator_label(),
            self.policy.name(),
            exit_name(self.exit),
            self.precision.name()
        )
    }

    /// The integrator's label, `auto` where the pilot rays choose it.
    pub fn integrator_label(&self) -> &'static str {
        match self.policy {
            Policy::Auto => "auto",
            _ => integrator_label(self.integrator),
        }
    }

    /// The paper's method: Sharma's integrator, the gradient heuristic, bisection exit.
    pub fn is_paper(&self) -> bool {
        self.integrator == IntegratorKind::Sharma
            && self.policy == Policy::Heuristic
            && self.exit == ExitMethod::Bisection
    }

    /// Tracer settings at `param` (step or tolerance relative to `scale`).
    pub fn settings(&self, param: f64, scale: f64) -> TraceSettings {
        let step = match self.policy {
            Policy::Fixed => StepSpec::Fixed(param * scale),
            Policy::Heuristic => StepSpec::Heuristic {
                min: param * scale / 8.0,
                max: param * scale,
                amplitude: None,
            },
            Policy::Adaptive => StepSpec::Adaptive {
                tolerance: param * scale,
                initial: None,
            },
            Policy::PerLength | Policy::Auto => StepSpec::Auto(param),
        };
        let accuracy = match step {
            StepSpec::Auto(a) => a,
            _ => grin_scene::DEFAULT_AUTO_ACCURACY,
        };
        TraceSettings {
            integrator: self.integrator,
            step,
            max_steps: MAX_STEPS,
            exit: self.exit,
            macro_cells: true,
            accuracy,
            estimate_limit: accuracy,
            opl_control: false,
        }
    }

    /// The parameters swept for this method.
    pub fn params(&self, quick: bool) -> Vec<f64> {
        let order = grin_trace::integrate::order(self.integrator) as i32;
        match self.policy {
            Policy::Fixed | Policy::Heuristic => {
                // Steps down to R/512 (R/4096 for the heuristic's minimum): below that every
                // 4th-order method is at the f64 floor. Fixed steps of the 2nd-order
                // methods go on to R/2048, where their errors are still 1e-10 and above:
                // their order on the C2 noise field is not settled at R/512.
                let finest = if self.policy == Policy::Fixed && order == 2 {
                    11
                } else {
                    9
                };
                let ks: Vec<i32> = if quick {
                    vec![2, 4, 6]
                } else {
                    (1..=finest).collect()
                };
                ks.into_iter().map(|k| 2f64.powi(-k)).collect()
            }
            Policy::PerLength | Policy::Auto => {
                // Exit-direction errors asked for: the decades the summary names, and
                // between (the same low-order limits as error control).
                // (Error per unit length: euler needs ~1/asked^2 steps, verlet 1/asked.)
                let finest = match order {
                    1 => 3,
                    2 => 5,
                    _ => 8,
                };
                let ks: Vec<i32> = if quick {
                    vec![2, 4, 6].into_iter().filter(|&k| k <= finest).collect()
                } else {
                    (2..=finest).collect()
                };
                ks.into_iter().map(|k| 10f64.powi(-k)).collect()
            }
            Policy::Adaptive => {
                // Low-order methods at tight tolerances need 10^5+ steps a ray: stop
                // where they would (euler 1e-6, verlet 1e-9, the others 1e-11).
                let finest = (3 + 3 * order).min(11);
                let ks: Vec<i32> = if quick {
                    vec![3, 5, 7].into_iter().filter(|&k| k <= finest).collect()
                } else {
                    (2..=finest).collect()
                };
                ks.into_iter().map(|k| 10f64.powi(-k)).collect()
            }
        }
    }
}

/// Step cap of every sweep run (no configuration swept needs more than ~10^4).
pub const MAX_STEPS: u32 = 1 << 20;

/// Every method of a sweep: all integrators and policies in both precisions; the quick
/// suite keeps the Hermite exit only, plus the paper's method with its bisection.
pub fn all_methods(quick: bool) -> Vec<Method> {
    let exits: &[ExitMethod] = if quick {
        &[ExitMethod::Hermite]
    } else {
        &[ExitMethod::Hermite, ExitMethod::Bisection]
    };
    let mut v = Vec::new();
    for &exit in exits {
        for precision in [Precision::F64, Precision::F32] {
            v.push(Method {
                integrator: IntegratorKind::Adaptive,
                policy: Policy::Auto,
                exit,
                precision,
            });
        }
    }
    for &integrator in &IntegratorKind::ALL {
        for policy in Policy::ALL.into_iter().filter(|&p| p != Policy::Auto) {
            for &exit in exits {
                for precision in [Precision::F64, Precision::F32] {
                    v.push(Method {
                        integrator,
                        policy,
                        exit,
                        precision,
                    });
                }
            }
        }
    }
    if quick {
        // The paper's method is one of the curves in every suite.
        for precision in [Precision::F64, Precision::F32] {
            v.push(Method {
                integrator: IntegratorKind::Sharma,
                policy: Policy::Heuristic,
                exit: ExitMethod::Bisection,
                precision,
            });
        }
    }
    v
}

/// The methods of the GPU column: every CPU f32 method with the Hermite exit (the
/// default; the bisection exit is held against the CPU in grin-gpu's tests) and the
/// paper's method; `--quick`: the paper's method, sharma at fixed steps, error control
/// per length (dopri) and `auto`.
pub fn gpu_methods(quick: bool) -> Vec<Method> {
    let gpu = |integrator, policy, exit| Method {
        integrator,
        policy,
        exit,
        precision: Precision::Gpu,
    };
    if quick {
        return vec![
            gpu(
                IntegratorKind::Sharma,
                Policy::Heuristic,
                ExitMethod::Bisection,
            ),
            gpu(IntegratorKind::Sharma, Policy::Fixed, ExitMethod::Hermite),
            gpu(
                IntegratorKind::Adaptive,
                Policy::PerLength,
                ExitMethod::Hermite,
            ),
            gpu(IntegratorKind::Adaptive, Policy::Auto, ExitMethod::Hermite),
        ];
    }
    all_methods(false)
        .into_iter()
        .filter(|m| {
            m.precision == Precision::F32 && (m.exit == ExitMethod::Hermite || m.is_paper())
        })
        .map(|m| Method {
            precision: Precision::Gpu,
            ..m
        })
        .collect()
}
