//! Per-pipeline specialisation of the GPU kernels (render and the marcher's stages),
//! before the driver sees them.
//!
//! The kernel chooses its integrator, step policy, interpolation and features with
//! pipeline-overridable constants (shaders/shared/types.wgsl). A driver may drop the
//! branches those constants rule out only late: Mesa (lavapipe, and the other Mesa
//! drivers) inlines every function call before it folds constants and removes dead
//! branches, so every field sample site of the kernel is first inlined with every
//! integrator and the 64-term tricubic sum. Here the constants are folded in with naga's
//! own `process_overrides`, every `if` and `switch` they decide is cut to the branch it
//! takes, and the functions nobody calls any more are dropped; wgpu then gets the
//! module as naga IR with no overrides left.

use std::collections::HashMap;
use std::sync::OnceLock;

use naga::{Block, Expression, Literal, Module, Statement, SwitchValue};

/// A kernel source the pipelines are specialised from.
#[derive(Clone, Copy, Debug, strum::IntoStaticStr)]
pub(crate) enum Kernel {
    /// shaders/render.wgsl: `render_main`, `render_deferred`.
    #[strum(serialize = "render.wgsl")]
    Render,
    /// shaders/stages.wgsl: the marcher's stages, one entry point each.
    #[strum(serialize = "stages.wgsl")]
    Stages,
}

impl Kernel {
    fn name(self) -> &'static str {
        self.into()
    }
}

type Parsed = Result<(Module, naga::valid::ModuleInfo), String>;

/// `kernel` parsed and validated once per process.
fn parsed(kernel: Kernel) -> Result<&'static (Module, naga::valid::ModuleInfo), String> {
    static RENDER: OnceLock<Parsed> = OnceLock::new();
    static STAGES: OnceLock<Parsed> = OnceLock::new();
    let (slot, source) = match kernel {
        Kernel::Render => (&RENDER, crate::shaders::RENDER_WGSL),
        Kernel::Stages => (&STAGES, crate::shaders::STAGES_WGSL),
    };
    slot.get_or_init(|| {
        let module = naga::front::wgsl::parse_str(source)
            .map_err(|e| format!("{}: {}", kernel.name(), e.message()))?;
        let info = validator()
            .validate(&module)
            .map_err(|e| format!("{}: {e}", kernel.name()))?;
        Ok((module, info))
    })
    .as_ref()
    .map_err(Clone::clone)
}

fn validator() -> naga::valid::Validator {
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::default(),
    )
}

/// `kernel`'s compute entry point `entry` with `constants` (name, value) folded in and
/// every branch they rule out removed. Errors name the step that failed; they mean a bug
/// in grin's shaders or here, never in the scene.
pub(crate) fn specialise(
    kernel: Kernel,
    entry: &str,
    constants: &[(&str, f64)],
) -> Result<Module, String> {
    let (module, info) = parsed(kernel)?;
    let name = kernel.name();
    let mut values = naga::back::PipelineConstants::default();
    for &(key, value) in constants {
        values.insert(key.to_owned(), value);
    }
    let (folded, _) = naga::back::pipeline_constants::process_overrides(
        module,
        info,
        Some((naga::ShaderStage::Compute, entry)),
        &values,
    )
    .map_err(|e| format!("{name} ({entry}): pipeline constants: {e}"))?;
    let mut out = folded.into_owned();
    let mut known = Known::of(&out);
    // Callees come before their callers in the arena, so a function that returns a
    // constant (`defer_medium()`) is known before any `if` that calls it is cut.
    for (handle, function) in out.functions.iter_mut() {
        let body = std::mem::take(&mut function.body);
        function.body = prune(body, &known, &function.expressions).0;
        // Names of `let`s in the cut branches would keep their calls alive for
        // `compact`; names are only for reading the output.
        function.named_expressions.clear();
        if let Some(value) = constant_return(function, &known) {
            known.returns.insert(handle, value);
        }
    }
    for entry_point in &mut out.entry_points {
        let body = std::mem::take(&mut entry_point.function.body);
        entry_point.function.body = prune(body, &known, &entry_point.function.expressions).0;
        entry_point.function.named_expressions.clear();
    }
    naga::compact::compact(&mut out, naga::compact::KeepUnused::No);
    validator()
        .validate(&out)
        .map_err(|e| format!("{name} ({entry}) specialised: {e:?}"))?;
    Ok(out)
}

/// The compute pipeline of `kernel`'s entry point `entry` on `device`, from the kernel
/// specialised for `constants` ([`specialise`]; nothing left for wgpu to override),
/// through the driver's pipeline `cache` when there is one.
pub(crate) fn compute_pipeline(
    device: &wgpu::Device,
    cache: Option<&wgpu::PipelineCache>,
    layout: &wgpu::PipelineLayout,
    kernel: Kernel,
    entry: &str,
    constants: &[(&str, f64)],
) -> Result<wgpu::ComputePipeline, String> {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(entry),
        source: wgpu::ShaderSource::Naga(std::borrow::Cow::Owned(specialise(
            kernel, entry, constants,
        )?)),
    });
    Ok(
        device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry),
            layout: Some(layout),
            module: &module,
            entry_point: Some(entry),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants: &[],
                zero_initialize_workgroup_memory: false,
            },
            cache,
        }),
    )
}

/// What is known to be constant: the literal value of each module-scope constant (after
/// `process_overrides` every former override is one), and the functions without
/// arguments that return a constant.
struct Known {
    constants: Vec<Option<Literal>>,
    returns: HashMap<naga::Handle<naga::Function>, Literal>,
}

impl Known {
    fn of(module: &Module) -> Self {
        Known {
            constants: module
                .constants
                .iter()
                .map(|(_, c)| match module.global_expressions[c.init] {
                    Expression::Literal(l) => Some(l),
                    _ => None,
                })
                .collect(),
            returns: HashMap::new(),
        }
    }
}

/// The value `function` always returns, where it takes no arguments and its body is only
/// `return <constant>` (after its own branches were cut).
fn constant_return(function: &naga::Function, known: &Known) -> Option<Literal> {
    if !function.arguments.is_empty() {
        return None;
    }
    let mut value = None;
    for statement in function.body.iter() {
        match *statement {
            Statement::Emit(_) => {}
            Statement::Return { value: Some(h) } => {
                value = literal(h, known, &function.expressions)
            }
            _ => return None,
        }
    }
    value
}

/// The value of expression `h`, where it is a constant.
fn literal(
    h: naga::Handle<Expression>,
    known: &Known,
    exprs: &naga::Arena<Expression>,
) -> Option<Literal> {
    match exprs[h] {
        Expression::Literal(l) => Some(l),
        Expression::Constant(c) => known.constants.get(c.index()).copied().flatten(),
        Expression::CallResult(f) => known.returns.get(&f).copied(),
        _ => None,
    }
}

/// The truth of condition `h` where constants decide it (`a && b` is false when either
/// side is a false constant, whatever the other is).
fn truth(
    h: naga::Handle<Expression>,
    known: &Known,
    exprs: &naga::Arena<Expression>,
) -> Option<bool> {
    use naga::{BinaryOperator as B, UnaryOperator as U};
    match exprs[h] {
        Expression::Unary {
            op: U::LogicalNot,
            expr,
        } => truth(expr, known, exprs).map(|b| !b),
        Expression::Binary {
            op: B::LogicalAnd,
            left,
            right,
        } => match (truth(left, known, exprs), truth(right, known, exprs)) {
            (Some(false), _) | (_, Some(false)) => Some(false),
            (Some(true), Some(true)) => Some(true),
            _ => None,
        },
        Expression::Binary {
            op: B::LogicalOr,
            left,
            right,
        } => match (truth(left, known, exprs), truth(right, known, exprs)) {
            (Some(true), _) | (_, Some(true)) => Some(true),
            (Some(false), Some(false)) => Some(false),
            _ => None,
        },
        _ => match literal(h, known, exprs)? {
            Literal::Bool(b) => Some(b),
            _ => None,
        },
    }
}

/// `block` with every constant-decided `if` replaced by the statements of the branch it
/// takes and every constant-selected `switch` cut to the case it takes; statements after
/// one that always leaves the block are dropped. Also says whether the block always
/// leaves (returns, breaks, continues or discards) at its end.
fn prune(block: Block, known: &Known, exprs: &naga::Arena<Expression>) -> (Block, bool) {
    let mut out = Block::with_capacity(block.len());
    for (statement, span) in block.span_into_iter() {
        let (statements, leaves) = match statement {
            Statement::If {
                condition,
                accept,
                reject,
            } => match truth(condition, known, exprs) {
                Some(taken) => {
                    let (b, leaves) = prune(if taken { accept } else { reject }, known, exprs);
                    out.extend_block(b);
                    if leaves {
                        return (out, true);
                    }
                    continue;
                }
                None => {
                    let (accept, a) = prune(accept, known, exprs);
                    let (reject, r) = prune(reject, known, exprs);
                    (
                        Statement::If {
                            condition,
                            accept,
                            reject,
                        },
                        a && r,
                    )
                }
            },
            Statement::Switch { selector, cases } => {
                let value = literal(selector, known, exprs);
                let taken = value.and_then(|v| taken_case(&cases, v));
                let cases: Vec<naga::SwitchCase> = match taken {
                    // The case taken and those it falls through to, as the only
                    // (default) case: a `break` in it still leaves the switch.
                    Some(first) => {
                        let mut body = Block::new();
                        for case in cases.into_iter().skip(first) {
                            let through = case.fall_through;
                            body.extend_block(case.body);
                            if !through {
                                break;
                            }
                        }
                        let (body, _) = prune(body, known, exprs);
                        vec![naga::SwitchCase {
                            value: SwitchValue::Default,
                            body,
                            fall_through: false,
                        }]
                    }
                    None => cases
                        .into_iter()
                        .map(|c| naga::SwitchCase {
                            body: prune(c.body, known, exprs).0,
                            ..c
                        })
                        .collect(),
                };
                (Statement::Switch { selector, cases }, false)
            }
            Statement::Loop {
                body,
                continuing,
                break_if,
            } => {
                let (body, _) = prune(body, known, exprs);
                let (continuing, _) = prune(continuing, known, exprs);
                (
                    Statement::Loop {
                        body,
                        continuing,
                        break_if,
                    },
                    false,
                )
            }
            Statement::Block(b) => {
                let (b, leaves) = prune(b, known, exprs);
                (Statement::Block(b), leaves)
            }
            s @ (Statement::Return { .. }
            | Statement::Kill
            | Statement::Break
            | Statement::Continue) => (s, true),
            s => (s, false),
        };
        out.push(statements, span);
        if leaves {
            return (out, true);
        }
    }
    (out, false)
}

/// The index of the case a switch on `value` starts at.
fn taken_case(cases: &[naga::SwitchCase], value: Literal) -> Option<usize> {
    let matches = |v: &SwitchValue| match (*v, value) {
        (SwitchValue::I32(a), Literal::I32(b)) => a == b,
        (SwitchValue::U32(a), Literal::U32(b)) => a == b,
        _ => false,
    };
    cases
        .iter()
        .position(|c| matches(&c.value))
        .or_else(|| cases.iter().position(|c| c.value == SwitchValue::Default))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu_data::{
        FLAG_EXIT_HERMITE, FLAG_HAS_MEDIUM, FLAG_TRICUBIC, INTEGRATOR_RK4, STEP_FIXED,
    };

    fn kernel(entry: &str, integrator: u32, flags: u32) -> Module {
        let constants = [
            ("PASS", 2.0),
            ("INTEGRATOR", f64::from(integrator)),
            ("STEP_POLICY", f64::from(STEP_FIXED)),
            ("FLAGS", f64::from(flags)),
            ("BOUNDS_BOX", 0.0),
            ("SKY_MAP", 0.0),
            ("SKY_PLATE", 0.0),
        ];
        specialise(Kernel::Render, entry, &constants).expect("the kernel specialises and validates")
    }

    fn has_function(module: &Module, name: &str) -> bool {
        module
            .functions
            .iter()
            .any(|(_, f)| f.name.as_deref() == Some(name))
    }

    #[test]
    fn a_kernel_keeps_only_the_integrator_and_interpolation_it_uses() {
        let trilinear = kernel("render_deferred", INTEGRATOR_RK4, FLAG_HAS_MEDIUM);
        assert!(trilinear.overrides.is_empty());
        assert!(has_function(&trilinear, "rk4_step"));
        assert!(has_function(&trilinear, "trilinear"));
        for gone in [
            "dopri_step",
            "euler_step",
            "verlet_step",
            "sharma_step",
            "tricubic",
        ] {
            assert!(
                !has_function(&trilinear, gone),
                "{gone} is still in the rk4 trilinear kernel"
            );
        }
        let tricubic = kernel(
            "render_deferred",
            INTEGRATOR_RK4,
            FLAG_HAS_MEDIUM | FLAG_TRICUBIC | FLAG_EXIT_HERMITE,
        );
        assert!(has_function(&tricubic, "tricubic"));
        // The full kernel, for scale: the cut leaves far fewer functions.
        let (full, _) = parsed(Kernel::Render).expect("render.wgsl parses");
        assert!(tricubic.functions.len() < full.functions.len());
        assert!(has_function(full, "dopri_step") && has_function(full, "tricubic"));
    }

    #[test]
    fn the_pass_without_the_medium_drops_the_march() {
        let first = kernel(
            "render_main",
            INTEGRATOR_RK4,
            FLAG_HAS_MEDIUM | FLAG_TRICUBIC,
        );
        let first_pass = specialise(
            Kernel::Render,
            "render_main",
            &[
                ("PASS", 1.0),
                ("INTEGRATOR", f64::from(INTEGRATOR_RK4)),
                ("STEP_POLICY", f64::from(STEP_FIXED)),
                ("FLAGS", f64::from(FLAG_HAS_MEDIUM | FLAG_TRICUBIC)),
                ("BOUNDS_BOX", 0.0),
                ("SKY_MAP", 0.0),
                ("SKY_PLATE", 0.0),
            ],
        )
        .expect("the first pass specialises");
        assert!(has_function(&first, "rk4_step"));
        assert!(
            !has_function(&first_pass, "rk4_step"),
            "the first pass still marches"
        );
    }

    /// Lavapipe compiles a new variant of a kernel for every new value of a uniform its
    /// branches read; per-band and per-frame values in a uniform buffer meant a compile
    /// per dispatch (docs/view.md). The render kernel reads no uniform buffer.
    #[test]
    fn the_render_kernel_reads_no_uniform_buffer() {
        let (module, _) = parsed(Kernel::Render).expect("render.wgsl parses");
        let params = module
            .global_variables
            .iter()
            .find(|(_, v)| v.name.as_deref() == Some("params"))
            .expect("the kernel has its frame parameters");
        assert!(matches!(params.1.space, naga::AddressSpace::Storage { .. }));
        for (_, v) in module.global_variables.iter() {
            assert!(
                v.space != naga::AddressSpace::Uniform,
                "{:?} is a uniform",
                v.name
            );
        }
    }

    #[test]
    fn a_switch_on_a_constant_keeps_the_case_taken_and_its_fall_through() {
        let cases = vec![
            naga::SwitchCase {
                value: SwitchValue::U32(1),
                body: Block::new(),
                fall_through: true,
            },
            naga::SwitchCase {
                value: SwitchValue::U32(2),
                body: Block::new(),
                fall_through: false,
            },
            naga::SwitchCase {
                value: SwitchValue::Default,
                body: Block::new(),
                fall_through: false,
            },
        ];
        assert_eq!(taken_case(&cases, Literal::U32(2)), Some(1));
        assert_eq!(taken_case(&cases, Literal::U32(1)), Some(0));
        assert_eq!(taken_case(&cases, Literal::U32(7)), Some(2));
        assert_eq!(taken_case(&cases[..2], Literal::U32(7)), None);
    }
}
