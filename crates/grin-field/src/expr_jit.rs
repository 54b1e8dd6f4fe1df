//! An expression field's tape (crate::expr_tape) compiled to machine code with Cranelift:
//! one function for n and its gradient, one for n alone. Arithmetic, square roots and
//! rounding to integers are instructions; the other functions (`sin`, `exp`, `powf`, ...)
//! are calls to the same Rust methods the interpreter uses, so the compiled code computes
//! exactly what [`Tape::eval`] does, operation for operation (tested bit for bit).
//!
//! The only unsafe code of the field crate is here: turning the finalized code's address
//! into a function pointer, sharing the finished code between threads, and freeing it.

#![allow(unsafe_code)]

use cranelift_codegen::ir::condcodes::FloatCC;
use cranelift_codegen::ir::{AbiParam, InstBuilder, MemFlagsData, Value, types};
use cranelift_codegen::settings::{self, Configurable};
use cranelift_frontend::{FunctionBuilder, FunctionBuilderContext};
use cranelift_jit::{JITBuilder, JITModule};
use cranelift_module::{Linkage, Module, default_libcall_names};

use crate::expr_tape::{Bin, Op, Tape, Un};

/// The compiled signature: inputs x, y, z, t; outputs n, dn/dx, dn/dy, dn/dz (n only for
/// the n function).
type Entry = extern "C" fn(*const f64, *mut f64);

/// A formula compiled to machine code.
pub struct Native {
    /// Owns the code's memory (freed on drop); never used otherwise after finalizing.
    module: Option<JITModule>,
    sample: Entry,
    n_only: Entry,
    /// Four points at once in two-lane vectors (inputs x[4], y[4], z[4], t[4]; outputs
    /// n[4], dn/dx[4], dn/dy[4], dn/dz[4]); `None` where the host's vector instructions
    /// cannot express the formula (then the scalar entry runs four times).
    sample4: Option<Entry>,
}

// SAFETY: after `finalize_definitions` the module is never touched again but by `Drop`
// (which has `&mut self`); the code it owns is immutable, keeps no state between calls
// and calls only pure Rust functions, so any number of threads may run it at once.
unsafe impl Send for Native {}
// SAFETY: as above: `&Native` gives access to the entry points only.
unsafe impl Sync for Native {}

impl std::fmt::Debug for Native {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Native(compiled formula)")
    }
}

impl Drop for Native {
    fn drop(&mut self) {
        if let Some(module) = self.module.take() {
            // SAFETY: the entry points die with `self`; nothing else points into the code.
            unsafe { module.free_memory() };
        }
    }
}

impl Native {
    /// Compile `tape`; `None` where the host has no Cranelift backend or compiling fails
    /// (the interpreter is used then).
    pub fn compile(tape: &Tape) -> Option<Native> {
        let mut flags = settings::builder();
        flags.set("opt_level", "speed").ok()?;
        flags.set("use_colocated_libcalls", "false").ok()?;
        flags.set("is_pic", "false").ok()?;
        let isa = cranelift_native::builder()
            .ok()?
            .finish(settings::Flags::new(flags))
            .ok()?;
        let mut jb = JITBuilder::with_isa(isa, default_libcall_names());
        for (name, f) in UNARY_CALLS {
            jb.symbol(*name, *f as *const u8);
        }
        for (name, f) in BINARY_CALLS {
            jb.symbol(*name, *f as *const u8);
        }
        let mut module = JITModule::new(jb);
        let sample = define(
            &mut module,
            tape,
            "grin_expr_sample",
            &tape.outputs,
            Width::One,
        )?;
        let n_only = define(
            &mut module,
            tape,
            "grin_expr_n",
            &tape.outputs[..1],
            Width::One,
        )?;
        let sample4 = define(
            &mut module,
            tape,
            "grin_expr_sample4",
            &tape.outputs,
            Width::Four,
        );
        module.finalize_definitions().ok()?;
        let sample_ptr = module.get_finalized_function(sample);
        let n_ptr = module.get_finalized_function(n_only);
        let sample4 = sample4.map(|id| {
            let ptr = module.get_finalized_function(id);
            // SAFETY: defined by `define_x2` with the signature `Entry` describes, final.
            unsafe { std::mem::transmute::<*const u8, Entry>(ptr) }
        });
        // SAFETY: both functions were defined above with the signature `Entry` describes
        // (two pointer arguments, no result, the platform's C convention) and are final.
        let (sample, n_only) = unsafe {
            (
                std::mem::transmute::<*const u8, Entry>(sample_ptr),
                std::mem::transmute::<*const u8, Entry>(n_ptr),
            )
        };
        Some(Native {
            module: Some(module),
            sample,
            n_only,
            sample4,
        })
    }

    /// n, dn/dx, dn/dy, dn/dz at four points (x, y, z per lane; one time t), as four
    /// lanes each: the same values as [`Self::sample`] at each point, bit for bit.
    #[inline]
    pub fn sample4(&self, p: [[f64; 4]; 3], t: f64, out: &mut [[f64; 4]; 4]) {
        match self.sample4 {
            Some(f) => {
                let inp = [p[0], p[1], p[2], [t; 4]];
                f(inp.as_ptr().cast(), out.as_mut_ptr().cast());
            }
            None => {
                for i in 0..4 {
                    let s = self.sample([p[0][i], p[1][i], p[2][i], t]);
                    for (o, v) in out.iter_mut().zip(s) {
                        o[i] = v;
                    }
                }
            }
        }
    }

    /// n, dn/dx, dn/dy, dn/dz at (x, y, z) and time t.
    #[inline]
    pub fn sample(&self, xyzt: [f64; 4]) -> [f64; 4] {
        let mut out = [0.0; 4];
        (self.sample)(xyzt.as_ptr(), out.as_mut_ptr());
        out
    }

    /// n alone.
    #[inline]
    pub fn n(&self, xyzt: [f64; 4]) -> f64 {
        let mut out = [0.0; 4];
        (self.n_only)(xyzt.as_ptr(), out.as_mut_ptr());
        out[0]
    }
}

/// How a defined function lays out its points.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Width {
    /// One point: inputs x, y, z, t; outputs one after another.
    One,
    /// Four points in two halves of two-lane vectors: inputs x[4], y[4], z[4], t[4];
    /// outputs likewise four lanes each.
    Four,
}

/// Define one function that evaluates the tape and stores the entries `outputs`, one
/// point at a time or four ([`Width`]). Arithmetic, square roots and rounding are
/// instructions (vector instructions for four points); the calls and comparisons run lane
/// by lane. `None` where an instruction does not compile on this host.
fn define(
    module: &mut JITModule,
    tape: &Tape,
    name: &str,
    outputs: &[u32],
    width: Width,
) -> Option<cranelift_module::FuncId> {
    let ptr = module.target_config().pointer_type();
    let mut ctx = module.make_context();
    ctx.func.signature.params.push(AbiParam::new(ptr));
    ctx.func.signature.params.push(AbiParam::new(ptr));
    let id = module
        .declare_function(name, Linkage::Local, &ctx.func.signature)
        .ok()?;
    let mut fctx = FunctionBuilderContext::new();
    // (value type, bytes between one input's start and the next's, halves).
    let (ty, stride, halves) = match width {
        Width::One => (types::F64, 8, 1),
        Width::Four => (types::F64X2, 32, 2),
    };
    {
        let mut b = FunctionBuilder::new(&mut ctx.func, &mut fctx);
        let block = b.create_block();
        b.append_block_params_for_function_params(block);
        b.switch_to_block(block);
        b.seal_block(block);
        let (inp, out) = (b.block_params(block)[0], b.block_params(block)[1]);
        // Only the entries the outputs need.
        let mut needed = vec![false; tape.ops.len()];
        for &o in outputs {
            needed[o as usize] = true;
        }
        for i in (0..tape.ops.len()).rev() {
            if needed[i] {
                match tape.ops[i] {
                    Op::Un(_, a) => needed[a as usize] = true,
                    Op::Bin(_, a, c) => {
                        needed[a as usize] = true;
                        needed[c as usize] = true;
                    }
                    _ => {}
                }
            }
        }
        let flags = MemFlagsData::trusted();
        for half in 0..halves {
            let mut vals: Vec<Option<Value>> = vec![None; tape.ops.len()];
            for (i, op) in tape.ops.iter().enumerate() {
                if !needed[i] {
                    continue;
                }
                let arg = |k: u32| vals[k as usize];
                let v = match *op {
                    Op::Const(c) => {
                        let s = b.ins().f64const(c);
                        match width {
                            Width::One => s,
                            Width::Four => b.ins().splat(ty, s),
                        }
                    }
                    Op::Var(k) => b
                        .ins()
                        .load(ty, flags, inp, i32::from(k) * stride + half * 16),
                    Op::Un(f, a) => {
                        let a = arg(a)?;
                        match f {
                            Un::Neg => b.ins().fneg(a),
                            Un::Abs => b.ins().fabs(a),
                            Un::Sqrt => b.ins().sqrt(a),
                            Un::Floor => b.ins().floor(a),
                            Un::Ceil => b.ins().ceil(a),
                            Un::Trunc => b.ins().trunc(a),
                            // f64::fract is x - trunc(x).
                            Un::Fract => {
                                let t = b.ins().trunc(a);
                                b.ins().fsub(a, t)
                            }
                            _ => {
                                let sym = unary_symbol(f);
                                per_lane(&mut b, width, &[a], |b, s| call(module, b, sym, s))?
                            }
                        }
                    }
                    Op::Bin(f, a, c) => {
                        let (a, c) = (arg(a)?, arg(c)?);
                        match f {
                            Bin::Add => b.ins().fadd(a, c),
                            Bin::Sub => b.ins().fsub(a, c),
                            Bin::Mul => b.ins().fmul(a, c),
                            Bin::Div => b.ins().fdiv(a, c),
                            Bin::Le => per_lane(&mut b, width, &[a, c], |b, s| {
                                let cond = b.ins().fcmp(FloatCC::LessThanOrEqual, s[0], s[1]);
                                let one = b.ins().f64const(1.0);
                                let zero = b.ins().f64const(0.0);
                                Some(b.ins().select(cond, one, zero))
                            })?,
                            Bin::Pow | Bin::Atan2 | Bin::Min | Bin::Max => {
                                let sym = binary_symbol(f);
                                per_lane(&mut b, width, &[a, c], |b, s| call(module, b, sym, s))?
                            }
                        }
                    }
                };
                vals[i] = Some(v);
            }
            for (k, &o) in outputs.iter().enumerate() {
                let v = vals[o as usize]?;
                let offset = i32::try_from(k).ok()? * stride + half * 16;
                b.ins().store(flags, v, out, offset);
            }
        }
        b.ins().return_(&[]);
        b.finalize(module.target_config());
    }
    module.define_function(id, &mut ctx).ok()?;
    module.clear_context(&mut ctx);
    Some(id)
}

/// `f` on scalars: on `args` themselves for one point, else on each lane of the
/// two-lane vectors `args`, the results put back together.
fn per_lane(
    b: &mut FunctionBuilder<'_>,
    width: Width,
    args: &[Value],
    mut f: impl FnMut(&mut FunctionBuilder<'_>, &[Value]) -> Option<Value>,
) -> Option<Value> {
    if width == Width::One {
        return f(b, args);
    }
    let mut lanes = [None; 2];
    for (lane, slot) in lanes.iter_mut().enumerate() {
        let scalars: Vec<Value> = args
            .iter()
            .map(|&a| b.ins().extractlane(a, lane as u8))
            .collect();
        *slot = Some(f(b, &scalars)?);
    }
    let v = b.ins().scalar_to_vector(types::F64X2, lanes[0]?);
    Some(b.ins().insertlane(v, lanes[1]?, 1))
}

/// A call of the Rust function registered as `sym` (f64 arguments, one f64 result).
fn call(
    module: &mut JITModule,
    b: &mut FunctionBuilder<'_>,
    sym: &str,
    args: &[Value],
) -> Option<Value> {
    let mut sig = module.make_signature();
    for _ in args {
        sig.params.push(AbiParam::new(types::F64));
    }
    sig.returns.push(AbiParam::new(types::F64));
    let callee = module.declare_function(sym, Linkage::Import, &sig).ok()?;
    let local = module.declare_func_in_func(callee, b.func);
    let inst = b.ins().call(local, args);
    b.inst_results(inst).first().copied()
}

macro_rules! unary_calls {
    ($($name:ident => $method:ident),* $(,)?) => {
        $(extern "C" fn $name(a: f64) -> f64 { a.$method() })*
        /// The functions of one argument compiled as calls, by symbol.
        const UNARY_CALLS: &[(&str, extern "C" fn(f64) -> f64)] =
            &[$((stringify!($name), $name)),*];
    };
}

unary_calls! {
    grin_expr_signum => signum,
    grin_expr_sin => sin,
    grin_expr_cos => cos,
    grin_expr_tan => tan,
    grin_expr_asin => asin,
    grin_expr_acos => acos,
    grin_expr_atan => atan,
    grin_expr_sinh => sinh,
    grin_expr_cosh => cosh,
    grin_expr_tanh => tanh,
    grin_expr_asinh => asinh,
    grin_expr_acosh => acosh,
    grin_expr_atanh => atanh,
    grin_expr_round => round,
    grin_expr_exp => exp,
    grin_expr_cbrt => cbrt,
    grin_expr_ln => ln,
    grin_expr_log2 => log2,
    grin_expr_log10 => log10,
}

extern "C" fn grin_expr_pow(a: f64, b: f64) -> f64 {
    a.powf(b)
}
extern "C" fn grin_expr_atan2(a: f64, b: f64) -> f64 {
    a.atan2(b)
}
extern "C" fn grin_expr_min(a: f64, b: f64) -> f64 {
    a.min(b)
}
extern "C" fn grin_expr_max(a: f64, b: f64) -> f64 {
    a.max(b)
}

/// The functions of two arguments compiled as calls, by symbol.
const BINARY_CALLS: &[(&str, extern "C" fn(f64, f64) -> f64)] = &[
    ("grin_expr_pow", grin_expr_pow),
    ("grin_expr_atan2", grin_expr_atan2),
    ("grin_expr_min", grin_expr_min),
    ("grin_expr_max", grin_expr_max),
];

/// The symbol of a function of two arguments that is compiled as a call.
fn binary_symbol(f: Bin) -> &'static str {
    match f {
        Bin::Pow => "grin_expr_pow",
        Bin::Atan2 => "grin_expr_atan2",
        Bin::Min => "grin_expr_min",
        Bin::Max => "grin_expr_max",
        // Compiled as instructions (never reaches here).
        Bin::Add | Bin::Sub | Bin::Mul | Bin::Div | Bin::Le => "grin_expr_none",
    }
}

/// The symbol of a function of one argument that is compiled as a call.
fn unary_symbol(f: Un) -> &'static str {
    match f {
        Un::Signum => "grin_expr_signum",
        Un::Sin => "grin_expr_sin",
        Un::Cos => "grin_expr_cos",
        Un::Tan => "grin_expr_tan",
        Un::Asin => "grin_expr_asin",
        Un::Acos => "grin_expr_acos",
        Un::Atan => "grin_expr_atan",
        Un::Sinh => "grin_expr_sinh",
        Un::Cosh => "grin_expr_cosh",
        Un::Tanh => "grin_expr_tanh",
        Un::Asinh => "grin_expr_asinh",
        Un::Acosh => "grin_expr_acosh",
        Un::Atanh => "grin_expr_atanh",
        Un::Round => "grin_expr_round",
        Un::Exp => "grin_expr_exp",
        Un::Cbrt => "grin_expr_cbrt",
        Un::Ln => "grin_expr_ln",
        Un::Log2 => "grin_expr_log2",
        Un::Log10 => "grin_expr_log10",
        // Compiled as instructions (never reaches here).
        Un::Neg | Un::Abs | Un::Sqrt | Un::Floor | Un::Ceil | Un::Trunc | Un::Fract => {
            "grin_expr_none"
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compiled_code_is_the_tape_bit_for_bit() {
        let texts = [
            "1.6 - 0.05*(x^2 + y^2)",
            "1 + 0.05*exp(-(x*x + (y-0.5)^2 + z*z)/0.1)",
            "sqrt(2 - (x^2 + y^2 + z^2)/0.36) + abs(sin(3*x)) * 1e-3",
            "1.3 + 0.1*tanh(x - y) + 0.01*atan2(y, x + 2) + 0.01*min(x, y) - 0.01*max(z, 0.1)",
            "1.5 + 0.1*fract(x) + 0.01*floor(3*y) + 0.01*ceil(z) + 0.01*trunc(x*y) + 0.01*round(z*7)",
            "2 + cosh(x)*0.1 - sinh(y)*0.1 + asinh(z)*0.1 + atan(x)*0.1 + cbrt(y)*0.1",
            "2 + ln(1.5 + x)*0.1 + log2(2 + y)*0.1 + log10(3 + z)*0.1 + (1.1 + x)^y*0.1",
            "1.2 + 0.1*asin(x/3) + 0.1*acos(y/3) + 0.1*atanh(z/3) + 0.1*acosh(2 + x^2) + signum(x)*0.01 + 0.01*tan(y)",
            "1 + t*x^3 + x^4*0.001 + y^0.5",
        ];
        for text in texts {
            let tape = Tape::new(text).expect("reads");
            let native = Native::compile(&tape).expect("compiles");
            let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
            let mut next = || {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                (seed >> 11) as f64 / (1u64 << 53) as f64 * 4.0 - 2.0
            };
            for _ in 0..2000 {
                let p = [next(), next(), next(), next()];
                let (want, got) = (tape.eval(p), native.sample(p));
                for k in 0..4 {
                    assert!(
                        want[k].to_bits() == got[k].to_bits()
                            || (want[k].is_nan() && got[k].is_nan()),
                        "{text} at {p:?}: output {k}: tape {} compiled {}",
                        want[k],
                        got[k]
                    );
                }
                assert_eq!(native.n(p).to_bits(), want[0].to_bits(), "{text}");
            }
            assert!(native.sample4.is_some(), "{text}: no four-point code");
            for _ in 0..500 {
                let pts: [[f64; 4]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| next()));
                let t = next();
                let mut out = [[0.0; 4]; 4];
                native.sample4(pts, t, &mut out);
                for i in 0..4 {
                    let want = tape.eval([pts[0][i], pts[1][i], pts[2][i], t]);
                    for k in 0..4 {
                        assert!(
                            want[k].to_bits() == out[k][i].to_bits()
                                || (want[k].is_nan() && out[k][i].is_nan()),
                            "{text}: four-point lane {i} output {k}: {} vs {}",
                            want[k],
                            out[k][i]
                        );
                    }
                }
            }
        }
    }
}
