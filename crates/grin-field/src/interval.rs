//! Interval arithmetic over `expr` formulas: an enclosure of n over a whole box, so that
//! n > 0 is proven everywhere in the bounds, not only at the check grid's nodes (a pocket
//! where n <= 0 narrower than the grid spacing passes any sampling; docs/physics.md,
//! failure mode 3). The formula is parsed a second time with exmex over [`Interval`];
//! each operation's result encloses every value the operation takes over its operands'
//! intervals, widened outward by one ulp per operation for roundoff. Branch and bound
//! over the bounds: a box whose enclosure is > 0 is done, one whose enclosure is <= 0 is
//! a counterexample, others are halved along their longest side, down to
//! [`MIN_BOX_REL`] of the bounds, where the box's centre is evaluated exactly.
//!
//! One concept, one file: the interval type, exmex's operator enclosures, branch and bound.

use std::f64::consts::{FRAC_PI_2, PI, TAU};
use std::str::FromStr;

use exmex::prelude::*;
use exmex::{BinOp, MakeOperators, Operator};
use glam::DVec3;

use crate::Bounds;

/// A closed interval [lo, hi] of reals (lo <= hi), or the whole line when unknown.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Interval {
    pub lo: f64,
    pub hi: f64,
}

const WHOLE: Interval = Interval {
    lo: f64::NEG_INFINITY,
    hi: f64::INFINITY,
};

impl Interval {
    pub fn point(x: f64) -> Self {
        Interval { lo: x, hi: x }
    }

    /// [min, max] of the candidates, widened one ulp outward; the whole line if any is
    /// NaN (the operation is undefined somewhere in the box).
    fn hull(values: &[f64]) -> Self {
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for &v in values {
            if v.is_nan() {
                return WHOLE;
            }
            lo = lo.min(v);
            hi = hi.max(v);
        }
        Interval {
            lo: lo.next_down(),
            hi: hi.next_up(),
        }
    }

    fn contains(self, x: f64) -> bool {
        self.lo <= x && x <= self.hi
    }

    fn is_point(self) -> bool {
        self.lo == self.hi
    }

    fn add(a: Self, b: Self) -> Self {
        Self::hull(&[a.lo + b.lo, a.hi + b.hi])
    }

    fn sub(a: Self, b: Self) -> Self {
        Self::hull(&[a.lo - b.hi, a.hi - b.lo])
    }

    fn neg(a: Self) -> Self {
        Interval {
            lo: -a.hi,
            hi: -a.lo,
        }
    }

    fn mul(a: Self, b: Self) -> Self {
        // 0 * inf is NaN in f64 but 0 in the limit a product of finite values takes.
        let p = |x: f64, y: f64| if x == 0.0 || y == 0.0 { 0.0 } else { x * y };
        Self::hull(&[p(a.lo, b.lo), p(a.lo, b.hi), p(a.hi, b.lo), p(a.hi, b.hi)])
    }

    fn div(a: Self, b: Self) -> Self {
        if b.contains(0.0) {
            return WHOLE;
        }
        Self::mul(a, Self::hull(&[1.0 / b.lo, 1.0 / b.hi]))
    }

    fn pow(a: Self, b: Self) -> Self {
        if b.is_point() && b.lo.fract() == 0.0 && b.lo.abs() <= 64.0 {
            let k = b.lo as i32;
            if k == 0 {
                return Self::point(1.0);
            }
            if k < 0 {
                return Self::div(Self::point(1.0), Self::pow(a, Self::point(-b.lo)));
            }
            let (l, h) = (a.lo.powi(k), a.hi.powi(k));
            if k % 2 == 0 && a.contains(0.0) {
                return Self::hull(&[0.0, l, h]);
            }
            return Self::hull(&[l, h]);
        }
        if a.lo >= 0.0 {
            // x^y is monotone in each argument on x >= 0: its extremes are at corners.
            return Self::hull(&[
                a.lo.powf(b.lo),
                a.lo.powf(b.hi),
                a.hi.powf(b.lo),
                a.hi.powf(b.hi),
            ]);
        }
        WHOLE
    }

    /// f non-decreasing on the interval (NaN outside its domain: the whole line).
    fn increasing(a: Self, f: fn(f64) -> f64) -> Self {
        Self::hull(&[f(a.lo), f(a.hi)])
    }

    fn decreasing(a: Self, f: fn(f64) -> f64) -> Self {
        Self::hull(&[f(a.hi), f(a.lo)])
    }

    fn abs(a: Self) -> Self {
        if a.contains(0.0) {
            Self::hull(&[0.0, a.lo.abs(), a.hi.abs()])
        } else {
            Self::hull(&[a.lo.abs(), a.hi.abs()])
        }
    }

    /// sin over [lo, hi]: the ends and every extremum pi/2 + k pi inside.
    fn sin(a: Self) -> Self {
        let width = a.hi - a.lo;
        if width.is_nan() || width >= TAU {
            return Self::hull(&[-1.0, 1.0]);
        }
        let mut v = vec![a.lo.sin(), a.hi.sin()];
        let mut k = ((a.lo - FRAC_PI_2) / PI).ceil();
        while FRAC_PI_2 + k * PI <= a.hi {
            v.push((FRAC_PI_2 + k * PI).sin());
            k += 1.0;
        }
        Self::hull(&v).clamp_to(-1.0, 1.0)
    }

    fn cos(a: Self) -> Self {
        Self::sin(Self::add(a, Self::point(FRAC_PI_2)))
    }

    fn tan(a: Self) -> Self {
        // Monotone between poles; a pole inside: unknown.
        let k = ((a.lo - FRAC_PI_2) / PI).ceil();
        if FRAC_PI_2 + k * PI <= a.hi {
            return WHOLE;
        }
        Self::increasing(a, f64::tan)
    }

    fn cosh(a: Self) -> Self {
        if a.contains(0.0) {
            Self::hull(&[1.0, a.lo.cosh(), a.hi.cosh()])
        } else {
            Self::hull(&[a.lo.cosh(), a.hi.cosh()])
        }
    }

    fn fract(a: Self) -> Self {
        if a.lo.floor() == a.hi.floor() {
            Self::hull(&[a.lo.fract(), a.hi.fract()])
        } else {
            Self::hull(&[-1.0, 1.0])
        }
    }

    fn min(a: Self, b: Self) -> Self {
        Interval {
            lo: a.lo.min(b.lo),
            hi: a.hi.min(b.hi),
        }
    }

    fn max(a: Self, b: Self) -> Self {
        Interval {
            lo: a.lo.max(b.lo),
            hi: a.hi.max(b.hi),
        }
    }

    fn clamp_to(self, lo: f64, hi: f64) -> Self {
        Interval {
            lo: self.lo.max(lo),
            hi: self.hi.min(hi),
        }
    }
}

impl FromStr for Interval {
    type Err = std::num::ParseFloatError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        // An integer literal is a double exactly (a point: `x^2` is an even power); any
        // other decimal need not be: enclose it.
        let x: f64 = s.parse()?;
        if x.fract() == 0.0 && x.abs() < 9.0e15 {
            return Ok(Interval::point(x));
        }
        Ok(Interval {
            lo: x.next_down(),
            hi: x.next_up(),
        })
    }
}

/// exmex's operators over intervals: the same names, priorities and arities as its
/// `FloatOpsFactory`, so every formula that parses for f64 parses here.
#[derive(Clone, Debug)]
pub struct IntervalOpsFactory;

impl MakeOperators<Interval> for IntervalOpsFactory {
    fn make<'a>() -> Vec<Operator<'a, Interval>> {
        let bin = |apply: fn(Interval, Interval) -> Interval, prio, is_commutative| BinOp {
            apply,
            prio,
            is_commutative,
        };
        let un = Operator::make_unary;
        vec![
            Operator::make_bin("^", bin(Interval::pow, 4, false)),
            Operator::make_bin("*", bin(Interval::mul, 2, true)),
            Operator::make_bin("/", bin(Interval::div, 3, false)),
            Operator::make_bin("+", bin(Interval::add, 0, true)),
            Operator::make_bin_unary("-", bin(Interval::sub, 1, false), Interval::neg),
            Operator::make_bin("atan2", bin(|_, _| Interval::hull(&[-PI, PI]), 0, false)),
            Operator::make_bin("min", bin(Interval::min, 0, true)),
            Operator::make_bin("max", bin(Interval::max, 0, true)),
            un("abs", Interval::abs),
            un("signum", |a| Interval::increasing(a, f64::signum)),
            un("sin", Interval::sin),
            un("cos", Interval::cos),
            un("tan", Interval::tan),
            un("asin", |a| Interval::increasing(a, f64::asin)),
            un("acos", |a| Interval::decreasing(a, f64::acos)),
            un("atan", |a| Interval::increasing(a, f64::atan)),
            un("sinh", |a| Interval::increasing(a, f64::sinh)),
            un("cosh", Interval::cosh),
            un("tanh", |a| Interval::increasing(a, f64::tanh)),
            un("asinh", |a| Interval::increasing(a, f64::asinh)),
            un("acosh", |a| Interval::increasing(a, f64::acosh)),
            un("atanh", |a| Interval::increasing(a, f64::atanh)),
            un("floor", |a| Interval::increasing(a, f64::floor)),
            un("round", |a| Interval::increasing(a, f64::round)),
            un("ceil", |a| Interval::increasing(a, f64::ceil)),
            un("trunc", |a| Interval::increasing(a, f64::trunc)),
            un("fract", Interval::fract),
            un("exp", |a| Interval::increasing(a, f64::exp)),
            un("sqrt", |a| Interval::increasing(a, f64::sqrt)),
            un("cbrt", |a| Interval::increasing(a, f64::cbrt)),
            un("ln", |a| Interval::increasing(a, f64::ln)),
            un("log2", |a| Interval::increasing(a, f64::log2)),
            un("log10", |a| Interval::increasing(a, f64::log10)),
            un("log", |a| Interval::increasing(a, f64::ln)),
            Operator::make_constant("PI", Interval::hull(&[PI])),
            Operator::make_constant("π", Interval::hull(&[PI])),
            Operator::make_constant("E", Interval::hull(&[std::f64::consts::E])),
            Operator::make_constant("e", Interval::hull(&[std::f64::consts::E])),
            Operator::make_constant("TAU", Interval::hull(&[TAU])),
            Operator::make_constant("τ", Interval::hull(&[TAU])),
        ]
    }
}

/// Smallest box the branch and bound splits to, as a fraction of the bounds' extent.
pub const MIN_BOX_REL: f64 = 1e-6;
/// Most boxes evaluated before the proof is given up (then the result says so).
pub const MAX_BOXES: usize = 200_000;

/// What the branch and bound found.
#[derive(Debug, Clone, PartialEq)]
pub enum Positivity {
    /// n > 0 at every point of the bounds, with the enclosure of n over them.
    Proven { n_lo: f64, n_hi: f64 },
    /// n <= 0 (or not finite) here: a counterexample.
    Fails { at: DVec3, n: f64 },
    /// Neither within the budget: n > 0 is not proven (the formula's intervals are too
    /// wide, or n touches 0).
    Unproven { boxes: usize },
}

/// A box of the branch and bound, ordered so that the heap pops the lowest enclosure.
struct Cell {
    n: Interval,
    a: DVec3,
    b: DVec3,
}

impl PartialEq for Cell {
    fn eq(&self, other: &Self) -> bool {
        self.n.lo.total_cmp(&other.n.lo).is_eq()
    }
}
impl Eq for Cell {}
impl PartialOrd for Cell {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Cell {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        // Reversed: BinaryHeap is a max-heap.
        other.n.lo.total_cmp(&self.n.lo)
    }
}

/// Prove n > 0 over `bounds` for the formula `eval_box` encloses, with `eval_point` the
/// formula itself (for counterexamples). Best first: the box with the lowest enclosure is
/// split next, so a pocket is found before the rest is proven, and when the lowest
/// enclosure is > 0 every remaining box is.
pub fn certify_positive(
    bounds: &Bounds,
    eval_box: &dyn Fn(DVec3, DVec3) -> Interval,
    eval_point: &dyn Fn(DVec3) -> f64,
) -> Positivity {
    let (lo, hi) = match *bounds {
        Bounds::Sphere { center, radius } => (center - radius, center + radius),
        Bounds::Box { min, max } => (min, max),
    };
    let min_size = MIN_BOX_REL * (hi - lo).max_element();
    let mut heap = std::collections::BinaryHeap::new();
    let mut boxes = 1;
    heap.push(Cell {
        n: enclosure(eval_box, lo, hi),
        a: lo,
        b: hi,
    });
    let mut unresolved = 0;
    let mut n_hi = f64::NEG_INFINITY;
    while let Some(Cell { n, a, b }) = heap.pop() {
        if n.lo > 0.0 {
            // Every box left has an enclosure above this one's.
            n_hi = heap.iter().fold(n.hi.max(n_hi), |m, c| m.max(c.n.hi));
            return if unresolved == 0 {
                Positivity::Proven { n_lo: n.lo, n_hi }
            } else {
                Positivity::Unproven { boxes }
            };
        }
        let centre = clamp_into(bounds, (a + b) * 0.5);
        let nc = eval_point(centre);
        if !(nc > 0.0 && nc.is_finite()) {
            return Positivity::Fails { at: centre, n: nc };
        }
        let size = b - a;
        if size.max_element() <= min_size {
            // n touches 0 here, or the enclosure stays wide: neither proven nor refuted.
            unresolved += 1;
            continue;
        }
        if boxes + 2 > MAX_BOXES {
            return Positivity::Unproven { boxes };
        }
        let axis = if size.x >= size.y && size.x >= size.z {
            0
        } else if size.y >= size.z {
            1
        } else {
            2
        };
        let mid = (a[axis] + b[axis]) * 0.5;
        let mut upper_a = a;
        upper_a[axis] = mid;
        let mut lower_b = b;
        lower_b[axis] = mid;
        for (ca, cb) in [(a, lower_b), (upper_a, b)] {
            if meets(bounds, ca, cb) {
                boxes += 1;
                heap.push(Cell {
                    n: enclosure(eval_box, ca, cb),
                    a: ca,
                    b: cb,
                });
            }
        }
    }
    if unresolved == 0 {
        Positivity::Proven {
            n_lo: f64::NAN,
            n_hi,
        }
    } else {
        Positivity::Unproven { boxes }
    }
}

/// The enclosure over [a, b]; a NaN end counts as unknown.
fn enclosure(eval_box: &dyn Fn(DVec3, DVec3) -> Interval, a: DVec3, b: DVec3) -> Interval {
    let n = eval_box(a, b);
    if n.lo.is_nan() || n.hi.is_nan() {
        WHOLE
    } else {
        n
    }
}

/// The box [a, b] meets the bounds.
fn meets(bounds: &Bounds, a: DVec3, b: DVec3) -> bool {
    match *bounds {
        Bounds::Sphere { center, radius } => {
            let nearest = center.clamp(a, b);
            (nearest - center).length_squared() <= radius * radius
        }
        Bounds::Box { .. } => true,
    }
}

/// `p`, or the nearest point of the bounds to it.
pub(crate) fn clamp_into(bounds: &Bounds, p: DVec3) -> DVec3 {
    match *bounds {
        Bounds::Sphere { center, radius } => {
            let d = p - center;
            let l = d.length();
            if l > radius {
                center + d * (radius / l)
            } else {
                p
            }
        }
        Bounds::Box { min, max } => p.clamp(min, max),
    }
}

/// A formula over intervals, with grin's number literals.
pub type IntervalFlat = FlatEx<Interval, IntervalOpsFactory, crate::expr::NumberLiteral>;

/// Parse `text` over intervals (the same grammar as the f64 formula).
pub fn parse(text: &str) -> Result<IntervalFlat, String> {
    IntervalFlat::parse(text).map_err(|e| e.msg().to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    type F64Flat = FlatEx<f64, exmex::FloatOpsFactory<f64>, crate::expr::NumberLiteral>;

    fn eval(text: &str, x: Interval) -> Interval {
        let ex = parse(text).expect("parses");
        ex.eval(&[x]).expect("evaluates")
    }

    fn iv(lo: f64, hi: f64) -> Interval {
        Interval { lo, hi }
    }

    /// Each operation's enclosure holds the values sampled over its interval.
    #[test]
    fn enclosures_hold_sampled_values() {
        let f64_ops = |text: &str| F64Flat::parse(text).expect("f64 parses");
        let e = eval("1e-3 * x", iv(1.0, 1.0));
        assert!(e.contains(1e-3) && e.hi - e.lo < 1e-18, "{e:?}");
        for text in [
            "x^2 - 2*x + 2",
            "sin(x) * cos(3*x)",
            "exp(-x^2 / 0.01)",
            "sqrt(abs(x)) + x^3",
            "1 / (2 + sin(x))",
            "tanh(x) - atan(x) + cosh(x)",
            "x^0.5",
            "min(x, 1 - x) + max(x, 0.3)",
            "fract(x) + floor(2*x)",
        ] {
            let f = f64_ops(text);
            for (lo, hi) in [(-1.0, 1.0), (0.1, 0.2), (2.0, 9.0), (0.0, 0.0)] {
                let e = eval(text, iv(lo, hi));
                for i in 0..=200 {
                    let x = lo + (hi - lo) * f64::from(i) / 200.0;
                    let v = f.eval(&[x]).expect("evaluates");
                    if v.is_nan() {
                        continue;
                    }
                    assert!(
                        e.lo <= v && v <= e.hi,
                        "{text} on [{lo}, {hi}]: {v} at {x} outside [{}, {}]",
                        e.lo,
                        e.hi
                    );
                }
            }
        }
    }

    #[test]
    fn sine_enclosure_is_tight_where_there_is_no_extremum() {
        let e = eval("sin(x)", iv(0.1, 0.2));
        assert!(
            e.lo >= 0.1f64.sin() - 1e-15 && e.hi <= 0.2f64.sin() + 1e-15,
            "{e:?}"
        );
        let e = eval("sin(x)", iv(1.0, 2.0));
        assert!(e.hi >= 1.0 && e.hi <= 1.0 + 1e-15, "{e:?}");
    }

    #[test]
    fn a_pocket_narrower_than_any_grid_is_found_and_a_positive_field_proven() {
        let ball = Bounds::Sphere {
            center: DVec3::ZERO,
            radius: 1.0,
        };
        let run = |text: &str| {
            let ex = parse(text).expect("parses");
            let f = F64Flat::parse(text).expect("parses");
            // Variables x, y, z in that (alphabetical) order in these formulas.
            certify_positive(
                &ball,
                &|a, b| {
                    ex.eval(&[iv(a.x, b.x), iv(a.y, b.y), iv(a.z, b.z)])
                        .unwrap_or(WHOLE)
                },
                &|p| f.eval(&[p.x, p.y, p.z]).unwrap_or(f64::NAN),
            )
        };
        // n = 1 - 2 exp(-r'^2 / 1e-6): n < 0 within ~0.8e-3 of (0.3, 0.1, -0.2).
        let pocket = "1 - 2*exp(-((x - 0.3)^2 + (y - 0.1)^2 + (z + 0.2)^2) / 1e-6) + 0*x*y*z";
        match run(pocket) {
            Positivity::Fails { at, n } => {
                assert!(n <= 0.0, "{n}");
                assert!((at - DVec3::new(0.3, 0.1, -0.2)).length() < 1e-3, "{at}");
            }
            other => panic!("pocket not found: {other:?}"),
        }
        match run("1.2 + 0.1*sin(9*x)*cos(7*y) - 0.05*z^2 + 0*x*y*z") {
            Positivity::Proven { n_lo, n_hi } => {
                assert!(n_lo > 1.0 && n_lo <= 1.05 && n_hi >= 1.2, "{n_lo} {n_hi}")
            }
            other => panic!("not proven: {other:?}"),
        }
    }
}
