use super::*;
use crate::analytic::Luneburg;
use crate::analytic::test_util::points_inside;

fn ball() -> Bounds {
    Bounds::Sphere {
        center: DVec3::new(0.0, 0.5, 0.0),
        radius: 0.6,
    }
}

#[test]
fn gaussian_gradient_is_exact() {
    let f = ExprField::new(
        "1 + 0.05*exp(-(x*x + (y-0.5)^2 + z*z)/0.1)",
        ball(),
        1.0,
        0.0,
    )
    .expect("valid");
    for p in points_inside(&f, 7) {
        let d = p - DVec3::new(0.0, 0.5, 0.0);
        let g = 0.05 * (-d.length_squared() / 0.1).exp();
        let s = f.sample(p);
        assert!((s.n - (1.0 + g)).abs() < 1e-14);
        let want = d * (-2.0 * g / 0.1);
        assert!(
            (s.grad_n - want).length() <= 1e-12 * want.length().max(1e-3),
            "{p}: {} vs {want}",
            s.grad_n
        );
    }
    let (lo, hi) = f.n_range();
    assert!(lo <= 1.0 + 0.05 * (-3.6f64).exp() && hi >= 1.05);
}

#[test]
fn luneburg_as_expression_matches_the_analytic_profile() {
    let lens = Luneburg::new(ball(), 1.0, None).expect("valid");
    let f = ExprField::new(
        "sqrt(2 - (x^2 + (y - 0.5)^2 + z^2) / 0.36)",
        ball(),
        1.0,
        0.0,
    )
    .expect("valid");
    for p in points_inside(&f, 7) {
        let (a, b) = (lens.sample(p), f.sample(p));
        assert!((a.n - b.n).abs() < 1e-14, "{p}");
        assert!(
            (a.grad_n - b.grad_n).length() <= 1e-12 * a.grad_n.length().max(1e-3),
            "{p}: {} vs {}",
            a.grad_n,
            b.grad_n
        );
    }
    // Sampled estimates bracket the exact values of the analytic lens.
    let (lo, hi) = f.n_range();
    assert!(lo <= lens.n_range().0 + 0.02 && hi >= std::f64::consts::SQRT_2 - 1e-12);
    assert!(
        f.max_grad_n() <= lens.max_grad_n() * 1.05 && f.max_grad_n() >= lens.max_grad_n() * 0.9
    );
}

#[test]
fn time_and_missing_coordinates() {
    let f = ExprField::new("1.2 + 0.01*sin(x - t)", ball(), 1.0, 0.5).expect("valid");
    let s = f.sample(DVec3::new(0.1, 0.4, 0.0));
    assert!((s.n - (1.2 + 0.01 * (0.1f64 - 0.5).sin())).abs() < 1e-15);
    assert!((s.grad_n.x - 0.01 * (0.1f64 - 0.5).cos()).abs() < 1e-15);
    assert_eq!((s.grad_n.y, s.grad_n.z), (0.0, 0.0));
    let c = ExprField::new("1.33", ball(), 1.0, 0.0).expect("constant");
    assert_eq!(c.sample(DVec3::ZERO).grad_n, DVec3::ZERO);
}

#[test]
fn with_time_moves_the_formula_and_rechecks_positivity() {
    let f = ExprField::new("1 + 0.5*sin(x + t)", ball(), 1.0, 0.0).expect("valid");
    let g = f.with_time(1.0).expect("still positive");
    let p = DVec3::new(0.2, 0.5, 0.1);
    assert!((g.n(p) - (1.0 + 0.5 * 1.2f64.sin())).abs() < 1e-15);
    assert_eq!(g.time(), 1.0);
    let f = ExprField::new("0.3 + t*x", ball(), 1.0, 0.0).expect("n = 0.3 at t = 0");
    let e = f.with_time(1.0).expect_err("n = 0.3 + x < 0 for x < -0.3");
    assert!(
        e.to_string().starts_with("expression `0.3 + t*x`: n = -"),
        "{e}"
    );
}

#[test]
fn parse_error_shows_expression_and_reason() {
    let e = ExprField::new("1 + (x*", ball(), 1.0, 0.0).expect_err("unbalanced");
    let m = e.to_string();
    assert!(
        m.starts_with("expression `1 + (x*`: does not parse: "),
        "{m}"
    );
}

#[test]
fn unknown_variable_is_named() {
    let e = ExprField::new("1 + 0.1*w", ball(), 1.0, 0.0).expect_err("w");
    assert_eq!(
        e.to_string(),
        "expression `1 + 0.1*w`: unknown variable `w` (allowed: x, y, z in world coordinates and t in seconds)"
    );
}

/// A pocket of n < 0 about 1.7e-3 across, far narrower than the check grid's spacing
/// (every node has n = 1): found by the interval bounds, with a point inside it.
#[test]
fn a_pocket_between_the_check_grid_nodes_is_refused() {
    let pocket = "1 - 2*exp(-((x - 0.31)^2 + (y - 0.17)^2 + (z + 0.23)^2) / 1e-6)";
    let t = std::time::Instant::now();
    let e = ExprField::new(pocket, ball(), 1.0, 0.0).expect_err("pocket");
    let FieldError::NonPositive { n, x, y, z, .. } = &e else {
        panic!("wrong error: {e}")
    };
    assert!(*n <= 0.0, "{e}");
    assert!(
        (DVec3::new(*x, *y, *z) - DVec3::new(0.31, 0.17, -0.23)).length() < 1e-3,
        "{e}"
    );
    assert!(
        e.to_string().contains("between the check grid's nodes"),
        "{e}"
    );
    eprintln!("pocket found in {:.3} s", t.elapsed().as_secs_f64());
    // The same width of dip that stays positive is proven so.
    let dip = "1 - 0.5*exp(-((x - 0.31)^2 + (y - 0.17)^2 + (z + 0.23)^2) / 1e-6)";
    let f = ExprField::new(dip, ball(), 1.0, 0.0).expect("positive");
    assert_eq!(f.positivity_note(), None);
}

#[test]
fn nonpositive_n_names_the_point() {
    // n = 1 - 2 (y - 0.5) is <= 0 for y >= 1, i.e. near the top of the ball (y up to 1.1).
    let e = ExprField::new("1 - 2*(y - 0.5)", ball(), 1.0, 0.0).expect_err("n <= 0 at the top");
    let FieldError::NonPositive { n, x, y, z, .. } = &e else {
        panic!("wrong error: {e}")
    };
    assert!(*n <= 0.0 && *y >= 1.0, "{e}");
    assert!(ball().contains(DVec3::new(*x, *y, *z)));
    let m = e.to_string();
    assert!(m.starts_with("expression `1 - 2*(y - 0.5)`: n = "), "{m}");
    assert!(
        m.contains(&format!("at ({x}, {y}, {z}) inside the medium")),
        "{m}"
    );
    // Non-finite: sqrt of a negative number.
    let e = ExprField::new("sqrt(0.5 - x)", ball(), 1.0, 0.0).expect_err("NaN for x > 0.5");
    assert!(e.to_string().contains("n is not finite (NaN)"), "{e}");
}

#[test]
fn unary_minus_before_a_power_is_refused_with_its_column() {
    for (text, column) in [
        ("1 + 0.01*exp(-x^2)", 14),
        ("1 + 0.01*exp(-(x/0.3)^2 - y*y)", 14),
        ("-x ^ 2 + 2", 1),
        ("1 + 0.01*exp(2*-sin(x)^2)", 16),
    ] {
        let e = ExprField::new(text, ball(), 1.0, 0.0)
            .expect_err(text)
            .to_string();
        assert!(e.contains(&format!("column {column}:")), "{text}: {e}");
        assert!(e.contains("tighter than `^`"), "{e}");
    }
    // What the message suggests, and minus signs that are not before a power, load.
    for text in [
        "1 + 0.01*exp(-(x^2))",
        "1 + 0.01*(-x)^2",
        "1.5 - x^2",
        "1 + 1e-3*exp(-x*x)",
        "1 + 2e-3^2 - 1e-3*y",
        "1 + 0.01*exp(-(x*x + y*y)/0.1)",
    ] {
        ExprField::new(text, ball(), 1.0, 0.0).unwrap_or_else(|e| panic!("{text}: {e}"));
    }
    // Why: exmex itself reads -x^2 as (-x)^2 (if this ever fails, the check above can go).
    let raw = exmex::parse::<f64>("-x^2").expect("parses");
    assert_eq!(raw.eval(&[0.5]).expect("evaluates"), 0.25);
    // The suggested form is the mathematical one.
    let f = ExprField::new("1 + 0.1*exp(-(x^2))", ball(), 1.0, 0.0).expect("valid");
    let s = f.sample(DVec3::new(0.5, 0.0, 0.0));
    assert!((s.n - (1.0 + 0.1 * (-0.25f64).exp())).abs() < 1e-14);
}

#[test]
fn scientific_notation_parses() {
    let f = ExprField::new(
        "1.000293 - 5e-5*exp(-y/2.5E-1) + 1.5e+0*0",
        ball(),
        1.0,
        0.0,
    )
    .expect("scientific notation");
    let p = DVec3::new(0.0, 0.5, 0.0);
    assert!((f.n(p) - (1.000293 - 5e-5 * (-2.0f64).exp())).abs() < 1e-15);
    let g = f.sample(p).grad_n.y;
    assert!((g - 5e-5 / 0.25 * (-2.0f64).exp()).abs() < 1e-15, "{g}");
}

#[test]
fn long_sums_parse_without_overflowing_the_stack() {
    // ~150 terms overflowed the main thread's stack inside exmex's derivative.
    let terms: Vec<String> = (0..60).map(|i| format!("1e-4*x^{}*y", i % 5)).collect();
    let text = format!("1.1 + {}", terms.join(" + "));
    let f = ExprField::new(&text, ball(), 1.0, 0.0).expect("60 terms, 240 operators");
    let p = DVec3::new(0.1, 0.5, 0.0);
    let want: f64 = 1.1
        + (0..60)
            .map(|i| 1e-4 * 0.1f64.powi(i % 5) * 0.5)
            .sum::<f64>();
    assert!((f.n(p) - want).abs() < 1e-12);
}

#[test]
fn oversized_and_overnested_formulas_are_refused_quickly() {
    let start = std::time::Instant::now();
    let long = format!("1.1 + 0.0001*({})", "x+".repeat(2100) + "x");
    let e = ExprField::new(&long, ball(), 1.0, 0.0).expect_err("too long");
    assert!(
        e.to_string()
            .contains("is 4216 characters long; at most 4096 are accepted"),
        "{e}"
    );
    let sum = format!("1.1{}", " + 1e-5*x".repeat(300));
    let e = ExprField::new(&sum, ball(), 1.0, 0.0).expect_err("too many operators");
    assert!(
        e.to_string()
            .contains("has 600 operators; at most 256 are accepted"),
        "{e}"
    );
    let nested = format!("1.5 + 0.1*{}x{}", "sin(".repeat(100), ")".repeat(100));
    let e = ExprField::new(&nested, ball(), 1.0, 0.0).expect_err("too deep");
    assert!(
        e.to_string()
            .contains("nests parentheses 100 deep; at most 32 levels are accepted"),
        "{e}"
    );
    // The deepest accepted composition still parses and differentiates.
    let deepest = format!("1.5 + 0.1*{}x{}", "sin(".repeat(31), ")".repeat(31));
    ExprField::new(&deepest, ball(), 1.0, 0.0).expect("31 nested sines");
    let widest = format!("1.1{}", " + 1e-5*x*y".repeat(85));
    ExprField::new(&widest, ball(), 1.0, 0.0).expect("85 terms, 255 operators");
    // Measured ~1 s in the test build; the old unbounded parse took minutes.
    assert!(
        start.elapsed().as_secs_f64() < 10.0,
        "{:?}",
        start.elapsed()
    );
}

#[test]
fn parse_errors_are_in_the_user_s_terms() {
    let e = ExprField::new("1 + 2 3", ball(), 1.0, 0.0).expect_err("missing operator");
    let m = e.to_string();
    assert!(!m.contains(" ops and "), "{m}");
    assert!(m.contains("does not parse"), "{m}");
}

/// Formulas from grin's scenes, tests and benches, and the forms people write.
const CORPUS: &[&str] = &[
    "1.6 - 0.05*(x^2 + y^2)",
    "1 + 0.05*exp(-(x*x + (y-0.5)^2 + z*z)/0.1)",
    "sqrt(2 - (x^2 + (y - 0.5)^2 + z^2) / 3.6)",
    "1 + 0.12*(1 - (x*x + (y - 0.6)*(y - 0.6) + (z + 0.6)*(z + 0.6))/3.6)",
    "1.0003 - 5e-3*exp(-((x*x+y*y-0.12)^2)/0.005)*(1+0.5*sin(3*z))",
    "1.25 - 0.25*tanh((x*x+y*y+z*z - 0.25)/0.002)",
    "1 - 0.3*exp(-((x-0.0833)^2 + (y-0.0833)^2 + (z-0.0833)^2)/0.0004)",
    "1 + 0.5*sin(x + t)",
    "1.2 + 0.01*sin(x - t)",
    "3 - 2*(y - 0.5) + 0.3*x*y/2*z",
    "20 + 2*x*3 + 4*(y + 1)*5 - 2*3/(4 + x^2) + 1 + 2 + 3*y",
    "2 + 0.1*(x + 2)^y + 0.1*x^3 - 0.01*y^4 + 0.1*(1.5 + z)^0.5 - -x*0.01",
    "1.3 + 0.1*cosh(x/3) - 0.1*sinh(y/3) + 0.1*ln(3 + z) + 0.1*log10(3 + x) + 0.1*asinh(y + 4) + 0.1*acosh(2 + x*y)",
    "PI/3 + 0.1*E*sin(TAU*x) + 0.01*log2(4 + y^2)",
    "1.1 + 1e-4*x^0*y + 1e-4*x^1*y + 1e-4*x^2*y + 1e-4*x^3*y + 1e-4*x^4*y",
];

/// A small generator of well-conditioned formulas for fuzzing the compiler: sums of
/// smooth terms around 1.5 (no cancellation that would make any rounding order
/// look wrong).
fn fuzz_formula(next: &mut impl FnMut() -> f64) -> String {
    let mut pick = |k: usize| ((next() * 0.5 + 0.5) * k as f64) as usize % k;
    let var = ["x", "y", "z", "t"];
    let funcs = ["sin", "cos", "tanh", "atan", "exp", "sqrt", "ln", "asinh"];
    let mut text = String::from("1.5");
    for _ in 0..(1 + pick(5)) {
        let c = format!("{:.3}", 0.05 + 0.2 * (pick(100) as f64 / 100.0));
        let a = var[pick(4)];
        let b = var[pick(4)];
        let f = funcs[pick(funcs.len())];
        let inner = match pick(6) {
            0 => format!("{a}*{b}"),
            1 => format!("({a} - {b}/2)^2"),
            2 => format!("{a}^3*0.1 + {b}"),
            3 => format!("{a}/(2 + {b}^2)"),
            4 => format!("-({a}^2)*2 + 0.5*{b}"),
            _ => format!("({a} + 3)^({b}/2) - {a}/(1 + {b}^2)*0.01"),
        };
        let inner = if f == "sqrt" || f == "ln" {
            format!("1 + ({inner})^2")
        } else if f == "exp" {
            format!("-(({inner})^2)")
        } else {
            inner
        };
        let op = ["+", "-", "+"][pick(3)];
        text.push_str(&format!(" {op} {c}*{f}({inner})"));
        if pick(3) == 0 {
            text.push_str(&format!("*{}", var[pick(4)]));
        }
    }
    text
}

/// The compiled formula against the interpreter: n within 2 ulp of the largest of
/// |n| and 1 (the same arithmetic but for integer powers as products; measured: bit
/// for bit at 95% of the points, 1.4 ulp at worst), the gradient (forward
/// differentiation against exmex's symbolic derivative) within 1e-15 of the largest
/// of |grad n| and 1 (measured: 2.2e-16 at worst).
#[test]
fn compiled_formula_matches_the_interpreter() {
    let bounds = Bounds::Box {
        min: DVec3::splat(-1.0),
        max: DVec3::splat(1.0),
    };
    let mut seed = 0x2545_f491_4f6c_dd1d_u64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut texts: Vec<String> = CORPUS.iter().map(|s| (*s).to_owned()).collect();
    for _ in 0..300 {
        texts.push(fuzz_formula(&mut next));
    }
    let (mut worst_n, mut worst_g, mut identical, mut total) = (0.0f64, 0.0f64, 0usize, 0usize);
    for text in &texts {
        let f = ExprField::new(text, bounds, 1.0, 0.3).unwrap_or_else(|e| panic!("{text}: {e}"));
        assert!(f.is_compiled(), "{text} is not compiled");
        for _ in 0..200 {
            let p = DVec3::new(next(), next(), next()) * 0.99;
            let (c, i) = (f.sample(p), f.sample_interpreted(p));
            let ulp = f64::EPSILON * i.n.abs().max(1.0);
            let dn = (c.n - i.n).abs() / ulp;
            let dg =
                (c.grad_n - i.grad_n).abs().max_element() / i.grad_n.abs().max_element().max(1.0);
            assert!(dn <= 2.0, "{text} at {p}: n {} vs {} ({dn} ulp)", c.n, i.n);
            assert!(
                dg <= 1e-15,
                "{text} at {p}: grad {} vs {} ({dg:e})",
                c.grad_n,
                i.grad_n
            );
            assert_eq!(f.n(p).to_bits(), c.n.to_bits(), "{text}: n() and sample()");
            worst_n = worst_n.max(dn);
            worst_g = worst_g.max(dg);
            identical += usize::from(c.n.to_bits() == i.n.to_bits());
            total += 1;
        }
    }
    eprintln!(
        "{} formulas, {total} points: n bit for bit at {identical}, worst {worst_n} ulp; \
             gradient worst {worst_g:e} relative",
        texts.len()
    );
}
