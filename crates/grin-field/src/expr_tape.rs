//! An expression field's formula as a tape: a list of operations on f64 in evaluation
//! order, holding n and its gradient (forward-mode differentiation: the chain rule applied
//! to each operation, exact up to roundoff). The tape is what `crate::expr_jit` compiles
//! to machine code; [`Tape::eval`] runs it in Rust, the reference the compiled code is
//! tested against bit for bit.
//!
//! The formula is read with the expression parser's rules (exmex, which loaded and
//! checked it first): `^` binds tighter than `/`, `/` than `*`, `*` than `-`, `-` than
//! `+`; operators of one kind group left to right, except that a commutative operator
//! between two literal numbers goes first (exmex's order); prefix operators (unary minus,
//! functions) bind tighter than `^` (grin refuses `-x^2` before it gets here); `atan2`,
//! `min`, `max` are written as calls. A formula this reader does not follow returns `None`
//! and stays with the interpreter.
//!
//! Two departures from the interpreter, both measured in the tests: integer powers 2, 3
//! and 4 are products (`powf` costs ~20 ns; a product is within 1 ulp of it per power),
//! and the gradient is differentiated forward rather than from exmex's symbolic
//! derivative (the same derivative, rounded in another order).
//!
//! Over 600 lines: one concept, the tape: its operations, their derivatives and its evaluation.

use std::collections::HashMap;

/// One operation. Operands are indices of earlier entries of the tape.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Op {
    Const(f64),
    /// Input `0..4`: x, y, z, t.
    Var(u8),
    Un(Un, u32),
    Bin(Bin, u32, u32),
}

/// Functions of one argument.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Un {
    Neg,
    Abs,
    Signum,
    Sin,
    Cos,
    Tan,
    Asin,
    Acos,
    Atan,
    Sinh,
    Cosh,
    Tanh,
    Asinh,
    Acosh,
    Atanh,
    Floor,
    Round,
    Ceil,
    Trunc,
    Fract,
    Exp,
    Sqrt,
    Cbrt,
    Ln,
    Log2,
    Log10,
}

/// Functions of two arguments.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Bin {
    Add,
    Sub,
    Mul,
    Div,
    /// `powf`.
    Pow,
    Atan2,
    Min,
    Max,
    /// 1 where a <= b, else 0 (the branch of `min`'s derivative).
    Le,
}

impl Un {
    /// The function as the interpreter computes it (Rust's f64 methods).
    pub fn apply(self, a: f64) -> f64 {
        match self {
            Un::Neg => -a,
            Un::Abs => a.abs(),
            Un::Signum => a.signum(),
            Un::Sin => a.sin(),
            Un::Cos => a.cos(),
            Un::Tan => a.tan(),
            Un::Asin => a.asin(),
            Un::Acos => a.acos(),
            Un::Atan => a.atan(),
            Un::Sinh => a.sinh(),
            Un::Cosh => a.cosh(),
            Un::Tanh => a.tanh(),
            Un::Asinh => a.asinh(),
            Un::Acosh => a.acosh(),
            Un::Atanh => a.atanh(),
            Un::Floor => a.floor(),
            Un::Round => a.round(),
            Un::Ceil => a.ceil(),
            Un::Trunc => a.trunc(),
            Un::Fract => a.fract(),
            Un::Exp => a.exp(),
            Un::Sqrt => a.sqrt(),
            Un::Cbrt => a.cbrt(),
            Un::Ln => a.ln(),
            Un::Log2 => a.log2(),
            Un::Log10 => a.log10(),
        }
    }

    fn named(name: &str) -> Option<Un> {
        Some(match name {
            "abs" => Un::Abs,
            "signum" => Un::Signum,
            "sin" => Un::Sin,
            "cos" => Un::Cos,
            "tan" => Un::Tan,
            "asin" => Un::Asin,
            "acos" => Un::Acos,
            "atan" => Un::Atan,
            "sinh" => Un::Sinh,
            "cosh" => Un::Cosh,
            "tanh" => Un::Tanh,
            "asinh" => Un::Asinh,
            "acosh" => Un::Acosh,
            "atanh" => Un::Atanh,
            "floor" => Un::Floor,
            "round" => Un::Round,
            "ceil" => Un::Ceil,
            "trunc" => Un::Trunc,
            "fract" => Un::Fract,
            "exp" => Un::Exp,
            "sqrt" => Un::Sqrt,
            "cbrt" => Un::Cbrt,
            "ln" | "log" => Un::Ln,
            "log2" => Un::Log2,
            "log10" => Un::Log10,
            _ => return None,
        })
    }
}

impl Bin {
    /// The operation as the interpreter computes it.
    pub fn apply(self, a: f64, b: f64) -> f64 {
        match self {
            Bin::Add => a + b,
            Bin::Sub => a - b,
            Bin::Mul => a * b,
            Bin::Div => a / b,
            Bin::Pow => a.powf(b),
            Bin::Atan2 => a.atan2(b),
            Bin::Min => a.min(b),
            Bin::Max => a.max(b),
            Bin::Le => f64::from(u8::from(a <= b)),
        }
    }
}

/// The tape: operations in evaluation order and the entries holding n, dn/dx, dn/dy,
/// dn/dz.
#[derive(Debug, Clone, PartialEq)]
pub struct Tape {
    pub ops: Vec<Op>,
    pub outputs: [u32; 4],
}

impl Tape {
    /// Read `text` and differentiate it; `None` where this reader does not follow it.
    pub fn new(text: &str) -> Option<Tape> {
        let tree = Parser::new(text)?.formula()?;
        let mut b = Builder::default();
        let (n, g) = b.emit(&tree);
        let zero = b.push(Op::Const(0.0));
        let outputs = [
            n,
            g[0].unwrap_or(zero),
            g[1].unwrap_or(zero),
            g[2].unwrap_or(zero),
        ];
        Some(Tape {
            ops: b.ops,
            outputs,
        })
    }

    /// n and grad n at (x, y, z) and time t, computed in Rust operation by operation.
    pub fn eval(&self, xyzt: [f64; 4]) -> [f64; 4] {
        let mut v = Vec::with_capacity(self.ops.len());
        for op in &self.ops {
            v.push(match *op {
                Op::Const(c) => c,
                Op::Var(i) => xyzt[usize::from(i)],
                Op::Un(f, a) => f.apply(v[a as usize]),
                Op::Bin(f, a, b) => f.apply(v[a as usize], v[b as usize]),
            });
        }
        self.outputs.map(|o| v[o as usize])
    }
}

/// A parsed formula.
#[derive(Debug, Clone, PartialEq)]
enum Tree {
    Num(f64),
    Var(u8),
    Un(Un, Box<Tree>),
    Bin(Bin, Box<Tree>, Box<Tree>),
}

/// Builds the tape: every entry once (equal operations on equal operands share one), an
/// operation on constants folded with the same arithmetic the tape would do.
#[derive(Debug, Default)]
struct Builder {
    ops: Vec<Op>,
    seen: HashMap<OpKey, u32>,
}

/// An [`Op`] as a hash key (constants by their bits).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum OpKey {
    Const(u64),
    Var(u8),
    Un(Un, u32),
    Bin(Bin, u32, u32),
}

/// A value's gradient: one entry per coordinate, `None` where it is zero by construction.
type Grad = [Option<u32>; 3];

impl Builder {
    fn push(&mut self, op: Op) -> u32 {
        let op = match op {
            Op::Un(f, a) => match self.ops[a as usize] {
                Op::Const(c) => Op::Const(f.apply(c)),
                _ => op,
            },
            Op::Bin(f, a, b) => match (self.ops[a as usize], self.ops[b as usize]) {
                (Op::Const(x), Op::Const(y)) => Op::Const(f.apply(x, y)),
                _ => op,
            },
            _ => op,
        };
        let key = match op {
            Op::Const(c) => OpKey::Const(c.to_bits()),
            Op::Var(i) => OpKey::Var(i),
            Op::Un(f, a) => OpKey::Un(f, a),
            Op::Bin(f, a, b) => OpKey::Bin(f, a, b),
        };
        if let Some(&id) = self.seen.get(&key) {
            return id;
        }
        let id = u32::try_from(self.ops.len()).unwrap_or(u32::MAX);
        self.ops.push(op);
        self.seen.insert(key, id);
        id
    }

    fn c(&mut self, v: f64) -> u32 {
        self.push(Op::Const(v))
    }
    fn un(&mut self, f: Un, a: u32) -> u32 {
        self.push(Op::Un(f, a))
    }
    fn bin(&mut self, f: Bin, a: u32, b: u32) -> u32 {
        self.push(Op::Bin(f, a, b))
    }

    /// `scale` times each component of `g` (zero stays zero).
    fn scaled(&mut self, g: Grad, scale: u32) -> Grad {
        g.map(|d| d.map(|d| self.bin(Bin::Mul, d, scale)))
    }

    /// Each component of `g` divided by `den`.
    fn divided(&mut self, g: Grad, den: u32) -> Grad {
        g.map(|d| d.map(|d| self.bin(Bin::Div, d, den)))
    }

    /// `a + b` per component, or `a - b` where `minus`.
    fn combined(&mut self, a: Grad, b: Grad, minus: bool) -> Grad {
        let mut out = [None; 3];
        for k in 0..3 {
            out[k] = match (a[k], b[k]) {
                (None, None) => None,
                (Some(x), None) => Some(x),
                (None, Some(y)) if minus => Some(self.un(Un::Neg, y)),
                (None, Some(y)) => Some(y),
                (Some(x), Some(y)) => Some(self.bin(if minus { Bin::Sub } else { Bin::Add }, x, y)),
            };
        }
        out
    }

    /// The value of `t` and its gradient.
    fn emit(&mut self, t: &Tree) -> (u32, Grad) {
        match t {
            Tree::Num(v) => (self.c(*v), [None; 3]),
            Tree::Var(i) => {
                let v = self.push(Op::Var(*i));
                let mut g = [None; 3];
                if let Some(slot) = g.get_mut(usize::from(*i)) {
                    *slot = Some(self.c(1.0));
                }
                (v, g)
            }
            Tree::Un(f, a) => {
                let (a, ga) = self.emit(a);
                let v = self.un(*f, a);
                let g = self.un_grad(*f, a, v, ga);
                (v, g)
            }
            Tree::Bin(f, a, b) => {
                let (a, ga) = self.emit(a);
                // powf(a, 0) is 1 and powf(a, 1) is a, exactly and for every a (the
                // rule below would give 0 * a^-1 = NaN at a = 0, where exmex's symbolic
                // derivative has 0).
                if *f == Bin::Pow
                    && let Tree::Num(k) = **b
                    && (k == 0.0 || k == 1.0)
                {
                    return if k == 0.0 {
                        (self.c(1.0), [None; 3])
                    } else {
                        (a, ga)
                    };
                }
                // An integer power 2..=4 is a product (the interpreter's powf, within 1
                // ulp per power).
                if *f == Bin::Pow
                    && let Tree::Num(k) = **b
                    && (k == 2.0 || k == 3.0 || k == 4.0)
                {
                    let sq = self.bin(Bin::Mul, a, a);
                    let gsq = self.product_grad(a, ga, a, ga);
                    return match k {
                        2.0 => (sq, gsq),
                        3.0 => {
                            let v = self.bin(Bin::Mul, sq, a);
                            (v, self.product_grad(sq, gsq, a, ga))
                        }
                        _ => {
                            let v = self.bin(Bin::Mul, sq, sq);
                            (v, self.product_grad(sq, gsq, sq, gsq))
                        }
                    };
                }
                let (b, gb) = self.emit(b);
                let v = self.bin(*f, a, b);
                let g = self.bin_grad(*f, (a, ga), (b, gb), v);
                (v, g)
            }
        }
    }

    /// d(a b) = da b + a db.
    fn product_grad(&mut self, a: u32, ga: Grad, b: u32, gb: Grad) -> Grad {
        let x = self.scaled(ga, b);
        let y = self.scaled(gb, a);
        self.combined(x, y, false)
    }

    fn un_grad(&mut self, f: Un, a: u32, v: u32, ga: Grad) -> Grad {
        if ga.iter().all(Option::is_none) {
            return ga;
        }
        let one = self.c(1.0);
        // d f(a) = f'(a) da: the factor f'(a), or (for quotients) its denominator.
        enum D {
            Times(u32),
            Over(u32),
            Zero,
        }
        let d = match f {
            Un::Neg => {
                return ga.map(|d| d.map(|d| self.un(Un::Neg, d)));
            }
            Un::Fract => return ga,
            Un::Abs => D::Times(self.un(Un::Signum, a)),
            Un::Signum | Un::Floor | Un::Round | Un::Ceil | Un::Trunc => D::Zero,
            Un::Sin => D::Times(self.un(Un::Cos, a)),
            Un::Cos => {
                let s = self.un(Un::Sin, a);
                D::Times(self.un(Un::Neg, s))
            }
            Un::Tan => {
                let c = self.un(Un::Cos, a);
                D::Over(self.bin(Bin::Mul, c, c))
            }
            Un::Asin | Un::Acos => {
                let aa = self.bin(Bin::Mul, a, a);
                let r = self.bin(Bin::Sub, one, aa);
                let s = self.un(Un::Sqrt, r);
                if f == Un::Asin {
                    D::Over(s)
                } else {
                    D::Over(self.un(Un::Neg, s))
                }
            }
            Un::Atan => {
                let aa = self.bin(Bin::Mul, a, a);
                D::Over(self.bin(Bin::Add, one, aa))
            }
            Un::Sinh => D::Times(self.un(Un::Cosh, a)),
            Un::Cosh => D::Times(self.un(Un::Sinh, a)),
            Un::Tanh => {
                let vv = self.bin(Bin::Mul, v, v);
                D::Times(self.bin(Bin::Sub, one, vv))
            }
            Un::Asinh => {
                let aa = self.bin(Bin::Mul, a, a);
                let r = self.bin(Bin::Add, aa, one);
                D::Over(self.un(Un::Sqrt, r))
            }
            Un::Acosh => {
                let aa = self.bin(Bin::Mul, a, a);
                let r = self.bin(Bin::Sub, aa, one);
                D::Over(self.un(Un::Sqrt, r))
            }
            Un::Atanh => {
                let aa = self.bin(Bin::Mul, a, a);
                D::Over(self.bin(Bin::Sub, one, aa))
            }
            Un::Exp => D::Times(v),
            Un::Sqrt => {
                let two = self.c(2.0);
                D::Over(self.bin(Bin::Mul, two, v))
            }
            Un::Cbrt => {
                let three = self.c(3.0);
                let vv = self.bin(Bin::Mul, v, v);
                D::Over(self.bin(Bin::Mul, three, vv))
            }
            Un::Ln => D::Over(a),
            Un::Log2 => {
                let k = self.c(std::f64::consts::LN_2);
                D::Over(self.bin(Bin::Mul, a, k))
            }
            Un::Log10 => {
                let k = self.c(std::f64::consts::LN_10);
                D::Over(self.bin(Bin::Mul, a, k))
            }
        };
        match d {
            D::Times(k) => self.scaled(ga, k),
            D::Over(k) => self.divided(ga, k),
            D::Zero => [None; 3],
        }
    }

    fn bin_grad(&mut self, f: Bin, (a, ga): (u32, Grad), (b, gb): (u32, Grad), v: u32) -> Grad {
        let none_a = ga.iter().all(Option::is_none);
        let none_b = gb.iter().all(Option::is_none);
        if none_a && none_b {
            return [None; 3];
        }
        match f {
            Bin::Add => self.combined(ga, gb, false),
            Bin::Sub => self.combined(ga, gb, true),
            Bin::Mul => self.product_grad(a, ga, b, gb),
            // d(a/b) = (da - (a/b) db) / b.
            Bin::Div => {
                let vgb = self.scaled(gb, v);
                let num = self.combined(ga, vgb, true);
                self.divided(num, b)
            }
            Bin::Pow => {
                if none_b {
                    // d a^b = b a^(b-1) da.
                    let one = self.c(1.0);
                    let bm1 = self.bin(Bin::Sub, b, one);
                    let p = self.bin(Bin::Pow, a, bm1);
                    let k = self.bin(Bin::Mul, b, p);
                    self.scaled(ga, k)
                } else {
                    // d a^b = a^b (ln a db + b da / a).
                    let ln = self.un(Un::Ln, a);
                    let x = self.scaled(gb, ln);
                    let ba = self.bin(Bin::Div, b, a);
                    let y = self.scaled(ga, ba);
                    let s = self.combined(x, y, false);
                    self.scaled(s, v)
                }
            }
            // d atan2(a, b) = (b da - a db) / (a^2 + b^2).
            Bin::Atan2 => {
                let x = self.scaled(ga, b);
                let y = self.scaled(gb, a);
                let num = self.combined(x, y, true);
                let aa = self.bin(Bin::Mul, a, a);
                let bb = self.bin(Bin::Mul, b, b);
                let den = self.bin(Bin::Add, aa, bb);
                self.divided(num, den)
            }
            // The gradient of the operand chosen: db + [a <= b] (da - db) for min.
            Bin::Min | Bin::Max => {
                let pick_a = if f == Bin::Min {
                    self.bin(Bin::Le, a, b)
                } else {
                    self.bin(Bin::Le, b, a)
                };
                let diff = self.combined(ga, gb, true);
                let chosen = self.scaled(diff, pick_a);
                self.combined(gb, chosen, false)
            }
            Bin::Le => [None; 3],
        }
    }
}

/// A recursive-descent reader of exmex's grammar (see the module comment).
struct Parser {
    toks: Vec<Tok>,
    at: usize,
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(f64),
    Name(String),
    Op(char),
    Open,
    Close,
    Comma,
}

/// Binary operators by binding, loosest first (exmex's priorities 0..4).
const LEVELS: [(char, Bin); 5] = [
    ('+', Bin::Add),
    ('-', Bin::Sub),
    ('*', Bin::Mul),
    ('/', Bin::Div),
    ('^', Bin::Pow),
];

/// Length of the number literal at the start of `s` (grin's literal pattern
/// `([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?`), 0 if none.
fn number_len(s: &[char]) -> usize {
    let digits = |from: usize| s[from..].iter().take_while(|c| c.is_ascii_digit()).count();
    let mut i = digits(0);
    if i > 0 {
        if s.get(i) == Some(&'.') {
            i += 1 + digits(i + 1);
        }
    } else if s.first() == Some(&'.') && digits(1) > 0 {
        i = 1 + digits(1);
    } else {
        return 0;
    }
    if matches!(s.get(i), Some('e' | 'E')) {
        let mut j = i + 1;
        if matches!(s.get(j), Some('+' | '-')) {
            j += 1;
        }
        let d = digits(j);
        if d > 0 {
            i = j + d;
        }
    }
    i
}

impl Parser {
    fn new(text: &str) -> Option<Parser> {
        let s: Vec<char> = text.chars().collect();
        let mut toks = Vec::new();
        let mut i = 0;
        while i < s.len() {
            let c = s[i];
            let len = number_len(&s[i..]);
            if len > 0 {
                let lit: String = s[i..i + len].iter().collect();
                toks.push(Tok::Num(lit.parse().ok()?));
                i += len;
            } else if c.is_alphabetic() || c == '_' {
                let start = i;
                while i < s.len() && (s[i].is_alphanumeric() || s[i] == '_') {
                    i += 1;
                }
                toks.push(Tok::Name(s[start..i].iter().collect()));
            } else {
                toks.push(match c {
                    '(' => Tok::Open,
                    ')' => Tok::Close,
                    ',' => Tok::Comma,
                    '+' | '-' | '*' | '/' | '^' => Tok::Op(c),
                    c if c.is_whitespace() => {
                        i += 1;
                        continue;
                    }
                    _ => return None,
                });
                i += 1;
            }
        }
        Some(Parser { toks, at: 0 })
    }

    fn peek(&self) -> Option<&Tok> {
        self.toks.get(self.at)
    }

    fn formula(mut self) -> Option<Tree> {
        let t = self.level(0)?;
        (self.at == self.toks.len()).then_some(t)
    }

    /// Operands joined by the operator of binding `level` (and tighter ones inside).
    fn level(&mut self, level: usize) -> Option<Tree> {
        let Some(&(sym, op)) = LEVELS.get(level) else {
            return self.prefixed();
        };
        let mut operands = vec![self.level(level + 1)?];
        while self.peek() == Some(&Tok::Op(sym)) {
            self.at += 1;
            operands.push(self.level(level + 1)?);
        }
        Some(join(operands, op))
    }

    /// Prefix operators (unary minus or plus, functions of one argument) on an operand.
    fn prefixed(&mut self) -> Option<Tree> {
        match self.peek()?.clone() {
            Tok::Op('-') => {
                self.at += 1;
                Some(Tree::Un(Un::Neg, Box::new(self.prefixed()?)))
            }
            Tok::Op('+') => {
                self.at += 1;
                self.prefixed()
            }
            Tok::Name(name) => {
                if let Some(f) = Un::named(&name) {
                    self.at += 1;
                    return Some(Tree::Un(f, Box::new(self.prefixed()?)));
                }
                let bin = match name.as_str() {
                    "atan2" => Some(Bin::Atan2),
                    "min" => Some(Bin::Min),
                    "max" => Some(Bin::Max),
                    _ => None,
                };
                self.at += 1;
                if let Some(f) = bin {
                    self.expect(&Tok::Open)?;
                    let a = self.level(0)?;
                    self.expect(&Tok::Comma)?;
                    let b = self.level(0)?;
                    self.expect(&Tok::Close)?;
                    return Some(Tree::Bin(f, Box::new(a), Box::new(b)));
                }
                Some(match name.as_str() {
                    "x" => Tree::Var(0),
                    "y" => Tree::Var(1),
                    "z" => Tree::Var(2),
                    "t" => Tree::Var(3),
                    "PI" | "π" => Tree::Num(std::f64::consts::PI),
                    "E" | "e" => Tree::Num(std::f64::consts::E),
                    "TAU" | "τ" => Tree::Num(std::f64::consts::TAU),
                    _ => return None,
                })
            }
            Tok::Num(v) => {
                self.at += 1;
                Some(Tree::Num(v))
            }
            Tok::Open => {
                self.at += 1;
                let t = self.level(0)?;
                self.expect(&Tok::Close)?;
                Some(t)
            }
            _ => None,
        }
    }

    fn expect(&mut self, tok: &Tok) -> Option<()> {
        (self.peek() == Some(tok)).then(|| self.at += 1)
    }
}

/// Whether `t` begins (`first`) or ends with a literal number as exmex's flat list of
/// operands sees it (a number under a prefix operator is folded into one).
fn literal_edge(t: &Tree, first: bool) -> bool {
    match t {
        Tree::Num(_) => true,
        Tree::Var(_) => false,
        Tree::Un(_, a) => matches!(**a, Tree::Num(_)),
        Tree::Bin(_, a, b) => literal_edge(if first { a } else { b }, first),
    }
}

/// Operands joined by one operator in exmex's order: a commutative operator between
/// two literal numbers first, then the rest left to right.
fn join(mut operands: Vec<Tree>, op: Bin) -> Tree {
    let commutative = matches!(op, Bin::Add | Bin::Mul);
    // `slots[i]` holds operand i until it is merged into its left neighbour.
    let mut order: Vec<usize> = (0..operands.len().saturating_sub(1)).collect();
    if commutative {
        let bonus: Vec<bool> = order
            .iter()
            .map(|&i| literal_edge(&operands[i], false) && literal_edge(&operands[i + 1], true))
            .collect();
        order.sort_by_key(|&i| !bonus[i]);
    }
    let mut slots: Vec<Option<Tree>> = operands.drain(..).map(Some).collect();
    for i in order {
        // The nearest live operand at or left of i, and right of i.
        let left = (0..=i).rev().find(|&k| slots[k].is_some());
        let right = (i + 1..slots.len()).find(|&k| slots[k].is_some());
        if let (Some(l), Some(r)) = (left, right)
            && let (Some(a), Some(b)) = (slots[l].take(), slots[r].take())
        {
            slots[l] = Some(Tree::Bin(op, Box::new(a), Box::new(b)));
        }
    }
    slots
        .into_iter()
        .flatten()
        .next()
        .unwrap_or(Tree::Num(f64::NAN))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn eval(text: &str, p: [f64; 4]) -> [f64; 4] {
        Tape::new(text).expect("reads").eval(p)
    }

    #[test]
    fn precedence_follows_exmex() {
        let p = [2.0, 3.0, 5.0, 0.0];
        assert_eq!(eval("x + y * z", p)[0], 17.0);
        assert_eq!(eval("x - y - z", p)[0], -6.0);
        assert_eq!(eval("x / y / z", p)[0], 2.0 / 3.0 / 5.0);
        assert_eq!(eval("x * y / z", p)[0], 2.0 * (3.0 / 5.0));
        assert_eq!(eval("-x * y", p)[0], -6.0);
        assert_eq!(eval("x ^ 2 * 3", p)[0], 12.0);
        assert_eq!(eval("sin(x)^2", p)[0], 2f64.sin().powi(2));
        assert_eq!(eval("2 ^ -x", p)[0], 0.25);
        assert_eq!(eval("max(x, y) - min(x, y)", p)[0], 1.0);
        assert_eq!(eval("1e-2*x + .5 + 3.", p)[0], 0.02 + 3.5);
        // x^0 and x^1 at x = 0: gradient 0 and 1, not NaN.
        let g = eval("x^0*y + x^1*y", [0.0, 2.0, 0.0, 0.0]);
        assert_eq!(g, [2.0, 2.0, 1.0, 0.0]);
    }

    #[test]
    fn gradient_is_the_chain_rule() {
        let p = [0.3, -0.7, 1.1, 0.0];
        let [n, gx, gy, gz] = eval("1.6 - 0.05*(x^2 + y^2)", p);
        assert_eq!(n, 1.6 - 0.05 * (0.09 + 0.49));
        assert!((gx + 0.1 * 0.3).abs() < 1e-16 && (gy - 0.07).abs() < 1e-16 && gz == 0.0);
        let [_, gx, gy, gz] = eval("exp(-x*y) + atan2(z, x)", p);
        let e = (0.21f64).exp();
        let r2 = 0.09 + 1.21;
        assert!((gx - (0.7 * e - 1.1 / r2)).abs() < 1e-14, "{gx}");
        assert!((gy - (-0.3 * e)).abs() < 1e-14, "{gy}");
        assert!((gz - 0.3 / r2).abs() < 1e-14, "{gz}");
    }

    #[test]
    fn refuses_what_it_does_not_read() {
        for text in ["x $ 2", "foo(x)", "(x + 1", "x +", "atan2(x)"] {
            assert!(Tape::new(text).is_none(), "{text}");
        }
    }
}
