//! Expression fields: a user formula n(x, y, z, t) in world coordinates (t = time in
//! seconds, fixed per field) parsed with exmex, with its exact gradient from exmex's
//! symbolic partial derivatives. Rejected at load: formulas that do not parse, unknown
//! variables, formulas beyond the size limits below, and n <= 0 or non-finite anywhere on
//! the check grid inside the medium, or between its nodes by interval bounds
//! (crate::interval).
//!
//! exmex differentiates recursively over its expression tree and its derivatives grow
//! with nesting, so a formula's length, its nesting depth and the size of its derivatives
//! are bounded ([`MAX_EXPR_CHARS`], [`MAX_EXPR_DEPTH`], [`MAX_DERIVATIVE_CHARS`]), and the
//! parse runs on a thread with its own large stack: no formula can overflow grin's stack
//! or keep it busy for minutes.
//!
//! One concept, one file: one formula's parse guards, load check and interval proof.

use exmex::prelude::*;
use exmex::{FloatOpsFactory, MatchLiteral, literal_matcher_from_pattern};
use glam::DVec3;

use crate::bounds::Bounds;
use crate::check::{CHECK_RESOLUTION, sample_stats};
use crate::expr_jit::Native;
use crate::expr_tape::Tape;
use crate::features::{Enclosed, FeatureMap};
use crate::field::{FieldError, FieldSample, IndexField};
use crate::interval::{Interval, IntervalFlat, Positivity, certify_positive};

/// The variables a formula may use: world coordinates x, y, z and time t (seconds).
pub const VARIABLES: [&str; 4] = ["x", "y", "z", "t"];

/// Longest formula accepted (characters).
pub const MAX_EXPR_CHARS: usize = 4096;

/// Most binary operators accepted. exmex's parse and derivative grow faster than linearly
/// with the number of operators (measured in a test build: 450 operators 1.4 s to load,
/// 1050 operators 11 s); at 256 the largest accepted formula loads in a fraction of that.
pub const MAX_EXPR_OPERATORS: usize = 256;

/// Deepest nesting of parentheses (each function call counts one level) accepted.
pub const MAX_EXPR_DEPTH: usize = 32;

/// Longest derivative accepted (characters of exmex's unparsed partial derivative): the
/// chain rule multiplies the size of deeply composed formulas, and every evaluation of the
/// field pays for each derivative.
pub const MAX_DERIVATIVE_CHARS: usize = 1 << 17;

/// Stack of the thread that parses and differentiates a formula: exmex recurses once per
/// operator of a long sum, ~1 KiB a level; 256 MiB is virtual memory, touched only as deep
/// as a formula goes.
const PARSE_STACK_BYTES: usize = 256 << 20;

// Numbers as people write them: 12, 1.5, .5, 3., and scientific notation 1e-5, 2.5E+3
// (exmex's default literal matcher has no exponent).
literal_matcher_from_pattern!(
    NumberLiteral,
    r"^([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?"
);

/// exmex's flat expression over f64 with grin's number literals.
type Flat = FlatEx<f64, FloatOpsFactory<f64>, NumberLiteral>;

/// Relative margin added to the sampled n range and max |grad n| (they are estimates
/// from the check grid, not bounds: the grid can step over a narrow peak).
const SAMPLED_MARGIN: f64 = 0.05;

/// One compiled formula and, for each of its variables, where to find it in (x, y, z, t).
#[derive(Debug, Clone)]
struct Compiled {
    ex: Flat,
    /// Index into (x, y, z, t) of each exmex variable (exmex orders them alphabetically).
    slots: Vec<usize>,
}

impl Compiled {
    fn new(ex: Flat) -> Self {
        let slots = ex
            .var_names()
            .iter()
            .map(|v| VARIABLES.iter().position(|k| k == v).unwrap_or(0))
            .collect();
        Compiled { ex, slots }
    }

    /// Evaluate; NaN if exmex refuses (cannot happen for a formula that passed `new`,
    /// and a NaN is caught by the load-time check).
    fn eval(&self, xyzt: &[f64; 4]) -> f64 {
        let mut vars = [0.0; 4];
        for (v, &s) in vars.iter_mut().zip(&self.slots) {
            *v = xyzt[s];
        }
        self.ex.eval(&vars[..self.slots.len()]).unwrap_or(f64::NAN)
    }
}

/// n(x, y, z, t) from a formula, with exact partial derivatives.
#[derive(Debug, Clone)]
pub struct ExprField {
    text: String,
    t: f64,
    n: Compiled,
    /// n over intervals (crate::interval), with the slots of its variables as for `n`.
    enclosure: (IntervalFlat, Vec<usize>),
    /// d n / d(x, y, z) over intervals, likewise.
    grad_enclosure: [Option<(IntervalFlat, Vec<usize>)>; 3],
    /// The formula's features (crate::features), built on first use.
    features: std::sync::OnceLock<FeatureMap>,
    /// Why n > 0 is not proven between the check grid's nodes, when it is not.
    positivity: Option<String>,
    /// d n / d(x, y, z); `None` where the formula does not use that coordinate.
    grad: [Option<Compiled>; 3],
    /// The formula and its gradient as machine code (crate::expr_jit), where the
    /// compiler reads the formula; the interpreter above stays the reference.
    native: Option<std::sync::Arc<Native>>,
    bounds: Bounds,
    ambient: f64,
    n_range: (f64, f64),
    max_grad_n: f64,
}

// IndexField requires Send + Sync: exmex's FlatEx<f64> holds plain data and fn pointers.
const _: fn() = || {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<Flat>();
};

/// Longest formula quoted whole in an error message.
const SHOWN_CHARS: usize = 120;

/// The formula as an error message quotes it: whole, or its start and length.
fn shown(text: &str) -> String {
    if text.chars().count() <= SHOWN_CHARS {
        text.to_owned()
    } else {
        let head: String = text.chars().take(SHOWN_CHARS).collect();
        format!("{head}... ({} characters)", text.chars().count())
    }
}

/// Check the size limits that do not need a parse: length and nesting depth.
fn check_size(text: &str) -> Result<(), String> {
    let chars = text.chars().count();
    if chars > MAX_EXPR_CHARS {
        return Err(format!(
            "is {chars} characters long; at most {MAX_EXPR_CHARS} are accepted"
        ));
    }
    let mut depth = 0usize;
    let mut deepest = 0usize;
    let mut operators = 0usize;
    let mut before = ['\0', '\0'];
    for c in text.chars() {
        // The sign of an exponent (1e-5) is part of a number, not an operator.
        let exponent_sign = matches!(c, '+' | '-')
            && matches!(before[1], 'e' | 'E')
            && (before[0].is_ascii_digit() || before[0] == '.');
        if matches!(c, '+' | '-' | '*' | '/' | '^') && !exponent_sign {
            operators += 1;
        }
        if !c.is_whitespace() {
            before = [before[1], c];
        }
        match c {
            '(' => {
                depth += 1;
                deepest = deepest.max(depth);
            }
            ')' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    if operators > MAX_EXPR_OPERATORS {
        return Err(format!(
            "has {operators} operators; at most {MAX_EXPR_OPERATORS} are accepted (bake a \
             larger formula with another tool and load it as a `baked` field)"
        ));
    }
    if deepest > MAX_EXPR_DEPTH {
        return Err(format!(
            "nests parentheses {deepest} deep; at most {MAX_EXPR_DEPTH} levels are accepted"
        ));
    }
    Ok(())
}

/// Refuse a unary minus whose operand is raised to a power (`-x^2`, `exp(-(r/s)^2)`):
/// exmex binds unary minus tighter than `^`, so it reads `-x^2` as `(-x)^2 = x^2`, the
/// opposite of the mathematical convention: every Gaussian written the usual way would be
/// silently wrong. The error names the column of the minus and both ways to write it.
fn check_unary_minus_power(text: &str) -> Result<(), String> {
    let chars: Vec<char> = text.chars().collect();
    let skip_ws = |mut i: usize| {
        while i < chars.len() && chars[i].is_whitespace() {
            i += 1;
        }
        i
    };
    // End (exclusive) of the parenthesised group opening at `i`.
    let group_end = |i: usize| {
        let mut depth = 0usize;
        for (k, &c) in chars.iter().enumerate().skip(i) {
            match c {
                '(' => depth += 1,
                ')' => {
                    depth = depth.saturating_sub(1);
                    if depth == 0 {
                        return k + 1;
                    }
                }
                _ => {}
            }
        }
        chars.len()
    };
    let mut prev: Option<char> = None;
    for (i, &c) in chars.iter().enumerate() {
        if c.is_whitespace() {
            continue;
        }
        let unary =
            c == '-' && matches!(prev, None | Some('(' | ',' | '+' | '-' | '*' | '/' | '^'));
        // An exponent's sign (1e-5) is part of its number.
        let exponent_sign = c == '-'
            && matches!(prev, Some('e' | 'E'))
            && i >= 2
            && (chars[i - 2].is_ascii_digit() || chars[i - 2] == '.');
        prev = Some(c);
        if !unary || exponent_sign {
            continue;
        }
        // The operand: a number, a name (with its call's arguments), or a group.
        let mut j = skip_ws(i + 1);
        if j < chars.len() && chars[j] == '(' {
            j = group_end(j);
        } else {
            let start = j;
            while j < chars.len() {
                let ch = chars[j];
                let sign_in_exponent = matches!(ch, '+' | '-')
                    && j > start
                    && matches!(chars[j - 1], 'e' | 'E')
                    && chars[start].is_ascii_digit();
                if ch.is_alphanumeric() || ch == '_' || ch == '.' || sign_in_exponent {
                    j += 1;
                } else {
                    break;
                }
            }
            let k = skip_ws(j);
            if j > start && k < chars.len() && chars[k] == '(' {
                j = group_end(k);
            }
        }
        let k = skip_ws(j);
        if k < chars.len() && chars[k] == '^' {
            let operand: String = chars[i + 1..j]
                .iter()
                .collect::<String>()
                .trim()
                .to_string();
            return Err(format!(
                "column {}: `-{operand}^...` would be read as `(-{operand})^...` (the expression parser binds a unary minus tighter than `^`); write `-({operand}^...)` for the usual meaning, or `(-{operand})^...` if that is what you mean",
                i + 1
            ));
        }
    }
    Ok(())
}

/// Parse `text` and differentiate it with respect to each coordinate it uses (on a thread
/// with a [`PARSE_STACK_BYTES`] stack). Errors are sentences for the user.
fn parse_with_gradient(text: &str) -> Result<Parsed, String> {
    check_size(text)?;
    check_unary_minus_power(text)?;
    let owned = text.to_owned();
    let worker = std::thread::Builder::new()
        .name("grin-expr-parse".into())
        .stack_size(PARSE_STACK_BYTES)
        .spawn(move || parse_on_this_thread(&owned))
        .map_err(|e| format!("cannot start the expression parser: {e}"))?;
    worker
        .join()
        .unwrap_or_else(|_| Err("the expression parser failed".to_owned()))
}

/// The formula, its partial derivatives, and both over intervals.
type Parsed = (
    Flat,
    [Option<Flat>; 3],
    IntervalFlat,
    [Option<IntervalFlat>; 3],
);

fn parse_on_this_thread(text: &str) -> Result<Parsed, String> {
    let ex = Flat::parse(text).map_err(|e| format!("does not parse: {}", parse_reason(e.msg())))?;
    if let Some(bad) = ex
        .var_names()
        .iter()
        .find(|v| !VARIABLES.contains(&v.as_str()))
    {
        return Err(format!(
            "unknown variable `{bad}` (allowed: x, y, z in world coordinates and t in seconds)"
        ));
    }
    let mut grad = [None, None, None];
    for (axis, g) in grad.iter_mut().enumerate() {
        if let Some(idx) = ex.var_names().iter().position(|v| v == VARIABLES[axis]) {
            let d = ex.clone().partial(idx).map_err(|e| {
                format!(
                    "cannot differentiate with respect to {}: {}",
                    VARIABLES[axis],
                    parse_reason(e.msg())
                )
            })?;
            let len = d.unparse().len();
            if len > MAX_DERIVATIVE_CHARS {
                return Err(format!(
                    "its derivative with respect to {} is {len} characters long (at most \
                     {MAX_DERIVATIVE_CHARS}): nest fewer functions",
                    VARIABLES[axis]
                ));
            }
            *g = Some(d);
        }
    }
    let enclosure = crate::interval::parse(text)
        .map_err(|e| format!("does not parse over intervals: {}", parse_reason(&e)))?;
    let mut grad_enclosure = [None, None, None];
    for (g, e) in grad.iter().zip(grad_enclosure.iter_mut()) {
        if let Some(g) = g {
            *e = Some(crate::interval::parse(g.unparse()).map_err(|e| {
                format!(
                    "its derivative does not parse over intervals: {}",
                    parse_reason(&e)
                )
            })?);
        }
    }
    Ok((ex, grad, enclosure, grad_enclosure))
}

/// exmex reports some syntax errors in terms of its own data structures ("we have 10 ops
/// and 12 node"); say what that means to the person who wrote the formula.
fn parse_reason(msg: &str) -> String {
    if msg.contains(" ops and ") && msg.contains(" node") {
        "an operator is missing an operand, or two operands have no operator between them"
            .to_owned()
    } else {
        msg.to_owned()
    }
}

impl ExprField {
    /// The expression GRIN rod of grin's ray-table benchmarks (the criterion benches, the
    /// numpy comparison in scripts/bench_numpy.py) and of the tests that price them:
    /// n = 1.6 - 0.05 (x^2 + y^2) in the box -2 <= x, y <= 2, 0 <= z <= 10, in air of 1.
    pub fn benchmark_rod() -> Self {
        let bounds = Bounds::Box {
            min: DVec3::new(-2.0, -2.0, 0.0),
            max: DVec3::new(2.0, 2.0, 10.0),
        };
        Self::new("1.6 - 0.05*(x^2 + y^2)", bounds, 1.0, 0.0)
            .expect("the benchmark rod's expression is valid")
    }

    /// Parse `text`, differentiate it, and check n > 0 on the check grid inside `bounds`.
    pub fn new(text: &str, bounds: Bounds, ambient: f64, t: f64) -> Result<Self, FieldError> {
        let err = |message: String| FieldError::Expr {
            expr: shown(text),
            message,
        };
        if !t.is_finite() {
            return Err(err(format!("time t = {t} is not finite")));
        }
        let (ex, grad, enclosure, grad_enclosure) = parse_with_gradient(text).map_err(err)?;
        let grad = grad.map(|g| g.map(Compiled::new));
        let with_slots = |e: IntervalFlat| {
            let slots = e
                .var_names()
                .iter()
                .map(|v| VARIABLES.iter().position(|k| k == v).unwrap_or(0))
                .collect();
            (e, slots)
        };
        let mut field = ExprField {
            text: text.to_owned(),
            t,
            n: Compiled::new(ex),
            enclosure: with_slots(enclosure),
            grad_enclosure: grad_enclosure.map(|e| e.map(with_slots)),
            features: std::sync::OnceLock::new(),
            positivity: None,
            grad,
            native: Tape::new(text)
                .and_then(|tape| Native::compile(&tape))
                .map(std::sync::Arc::new),
            bounds,
            ambient,
            n_range: (0.0, 0.0),
            max_grad_n: 0.0,
        };
        field.update_sampled_ranges()?;
        Ok(field)
    }

    /// The same formula at time `t` (for animation), re-checked for n > 0 at that time.
    /// Reuses the parsed formula and its derivatives.
    pub fn with_time(&self, t: f64) -> Result<Self, FieldError> {
        if !t.is_finite() {
            return Err(FieldError::Expr {
                expr: self.text.clone(),
                message: format!("time t = {t} is not finite"),
            });
        }
        let mut field = ExprField {
            t,
            features: std::sync::OnceLock::new(),
            ..self.clone()
        };
        field.update_sampled_ranges()?;
        Ok(field)
    }

    /// Sample the check grid: fail where n <= 0 or is not finite, else store the sampled
    /// n range and max |grad n| (widened by [`SAMPLED_MARGIN`]). Then prove n > 0 between
    /// the nodes too, by interval bounds over the whole bounds: fail on a pocket the grid
    /// stepped over, and say so (a warning) when neither proof nor pocket is found.
    fn update_sampled_ranges(&mut self) -> Result<(), FieldError> {
        let label = format!("expression `{}`", shown(&self.text));
        let stats = sample_stats(self, &label, CHECK_RESOLUTION)?;
        self.positivity = None;
        match self.certify() {
            Positivity::Proven { .. } => {}
            Positivity::Fails { at, n } => {
                return Err(FieldError::NonPositive {
                    field: format!("{label} (between the check grid's nodes)"),
                    n,
                    x: at.x,
                    y: at.y,
                    z: at.z,
                });
            }
            Positivity::Unproven { boxes } => {
                let why = format!(
                    "{label}: n > 0 is checked at the {CHECK_RESOLUTION}^3 check grid's nodes \
                     but could not be proven between them (interval bounds, {boxes} boxes): \
                     a pocket of n <= 0 narrower than the grid would not be seen"
                );
                self.positivity = Some(why);
            }
        }
        let pad = SAMPLED_MARGIN * (stats.n_max - stats.n_min);
        self.n_range = (
            (stats.n_min - pad).max(stats.n_min * 0.5),
            stats.n_max + pad,
        );
        self.max_grad_n = stats.max_grad_n * (1.0 + SAMPLED_MARGIN);
        Ok(())
    }

    /// A formula over intervals, evaluated over the box [a, b] at this field's time
    /// (`None` where the evaluation fails).
    fn enclose(
        &self,
        (ex, slots): &(IntervalFlat, Vec<usize>),
        a: DVec3,
        b: DVec3,
    ) -> Option<Interval> {
        let ranges = [
            Interval { lo: a.x, hi: b.x },
            Interval { lo: a.y, hi: b.y },
            Interval { lo: a.z, hi: b.z },
            Interval::point(self.t),
        ];
        let vars: Vec<Interval> = slots.iter().map(|&s| ranges[s]).collect();
        ex.eval(&vars).ok()
    }

    /// Where the formula has features a step could pass over, and how long steps may be
    /// there (crate::features), built on first use.
    pub fn feature_map(&self) -> &FeatureMap {
        self.features
            .get_or_init(|| FeatureMap::build(self, &self.bounds))
    }

    /// Interval branch and bound of n over the bounds (crate::interval).
    fn certify(&self) -> Positivity {
        let eval_box = |a: DVec3, b: DVec3| self.enclose(&self.enclosure, a, b).unwrap_or_default();
        let eval_point = |p: DVec3| self.n.eval(&[p.x, p.y, p.z, self.t]);
        // An evaluation error gives the default [0, 0]: not > 0, so the box is split.
        certify_positive(&self.bounds, &eval_box, &eval_point)
    }

    /// Why n > 0 is not proven between the check grid's nodes (`None`: it is proven).
    pub fn positivity_note(&self) -> Option<&str> {
        self.positivity.as_deref()
    }

    /// The formula as written.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// The time at which the formula is evaluated.
    pub fn time(&self) -> f64 {
        self.t
    }
}

impl Enclosed for ExprField {
    fn grad_at(&self, p: DVec3) -> DVec3 {
        self.sample(p).grad_n
    }
    fn grad_over(&self, lo: DVec3, hi: DVec3) -> [Interval; 3] {
        [0, 1, 2].map(|k| match &self.grad_enclosure[k] {
            // An evaluation that fails proves nothing: the whole line.
            Some(e) => self.enclose(e, lo, hi).unwrap_or(Interval {
                lo: f64::NEG_INFINITY,
                hi: f64::INFINITY,
            }),
            None => Interval::point(0.0),
        })
    }
    fn n_min_over(&self, lo: DVec3, hi: DVec3) -> f64 {
        match self.enclose(&self.enclosure, lo, hi) {
            Some(n) if n.lo > 0.0 => n.lo,
            _ => self.n_range.0,
        }
    }
}

impl ExprField {
    /// n and grad n by the interpreter (exmex and its symbolic derivatives): the
    /// reference the compiled code is tested against.
    pub fn sample_interpreted(&self, p: DVec3) -> FieldSample<f64> {
        let xyzt = [p.x, p.y, p.z, self.t];
        let d = |g: &Option<Compiled>| g.as_ref().map_or(0.0, |c| c.eval(&xyzt));
        FieldSample {
            n: self.n.eval(&xyzt),
            grad_n: DVec3::new(d(&self.grad[0]), d(&self.grad[1]), d(&self.grad[2])),
        }
    }

    /// Whether the formula runs as machine code (else it is interpreted).
    pub fn is_compiled(&self) -> bool {
        self.native.is_some()
    }
}

impl IndexField for ExprField {
    fn warnings(&self) -> Vec<String> {
        self.positivity.iter().cloned().collect()
    }

    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        match &self.native {
            Some(code) => {
                let [n, gx, gy, gz] = code.sample([p.x, p.y, p.z, self.t]);
                FieldSample {
                    n,
                    grad_n: DVec3::new(gx, gy, gz),
                }
            }
            None => self.sample_interpreted(p),
        }
    }
    fn sample4(&self, p: [[f64; 4]; 3], out: &mut [[f64; 4]; 4]) {
        match &self.native {
            Some(code) => code.sample4(p, self.t, out),
            None => crate::field::sample4_each(self, p, out),
        }
    }
    fn n(&self, p: DVec3) -> f64 {
        match &self.native {
            Some(code) => code.n([p.x, p.y, p.z, self.t]),
            None => self.n.eval(&[p.x, p.y, p.z, self.t]),
        }
    }
    fn bounds(&self) -> Bounds {
        self.bounds
    }
    fn ambient_index(&self) -> f64 {
        self.ambient
    }
    /// Sampled on the check grid, widened by 5% of the span.
    fn n_range(&self) -> (f64, f64) {
        self.n_range
    }
    /// Sampled on the check grid, plus 5%.
    fn max_grad_n(&self) -> f64 {
        self.max_grad_n
    }
    fn describe(&self) -> String {
        format!("expr n = {}", self.text)
    }
    fn step_cap(&self, p: DVec3, reach: f64) -> f64 {
        self.feature_map().step_cap(p, reach)
    }
    fn has_local_step_limits(&self) -> bool {
        self.feature_map().has_caps()
    }
    fn feature_points(&self) -> Vec<DVec3> {
        self.feature_map().points().to_vec()
    }
}

#[cfg(test)]
mod tests;
