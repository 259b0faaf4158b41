//! Expressions compiled for many particles at once.
//!
//! # Algorithm
//! The sub-expressions that do not depend on a state (parameters, inputs, time and
//! their functions) are *uniform*: the same for every particle. They are evaluated
//! once per call, as scalars. What remains is a straight-line list of instructions,
//! each a loop over the particles ("lanes") writing one register: an interpreter
//! whose dispatch cost is paid once per instruction and call, not per particle, and
//! whose loops the compiler vectorises. Registers are single-assignment, so each
//! instruction reads only lower-numbered registers.
//!
//! # Complexity
//! One pass over the `M` lanes per lane node of the expressions, plus the uniform
//! nodes once per call.

use crate::expr::{BinOp, Expr, Function, Node, Var};

/// Where an instruction reads a value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Operand {
    /// Column of state `i`.
    State(usize),
    /// A register (lane values).
    Reg(usize),
    /// A uniform value (the same for every lane), by slot.
    Uniform(usize),
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Instr {
    Bin(BinOp, Operand, Operand),
    Powi(Operand, i32),
    Neg(Operand),
    Call1(Function, Operand),
    Call2(Function, Operand, Operand),
}

/// Several expressions compiled together (they share the uniform values).
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    uniforms: Vec<Expr>,
    /// Instruction `k` writes register `k`.
    instrs: Vec<Instr>,
    results: Vec<Operand>,
}

/// An integer exponent small enough for repeated multiplication.
pub(crate) fn integer_exponent(e: &Expr) -> Option<i32> {
    match e.node {
        Node::Num(v) if v.fract() == 0.0 && v.abs() <= 64.0 => Some(v as i32),
        _ => None,
    }
}

/// A read-only view of an operand's values.
#[derive(Debug, Clone, Copy)]
pub enum Values<'a> {
    /// One value per lane.
    Lanes(&'a [f64]),
    /// The same value for every lane.
    Scalar(f64),
}

impl Values<'_> {
    /// The value of lane `k`.
    #[inline(always)]
    pub fn at(&self, k: usize) -> f64 {
        match self {
            Values::Lanes(v) => v[k],
            Values::Scalar(s) => *s,
        }
    }
}

#[inline(always)]
fn unary(dst: &mut [f64], a: Values, f: impl Fn(f64) -> f64) {
    match a {
        Values::Lanes(a) => {
            for (d, &x) in dst.iter_mut().zip(a) {
                *d = f(x);
            }
        }
        Values::Scalar(s) => dst.fill(f(s)),
    }
}

#[inline(always)]
fn binary(dst: &mut [f64], a: Values, b: Values, f: impl Fn(f64, f64) -> f64) {
    match (a, b) {
        (Values::Lanes(a), Values::Lanes(b)) => {
            for ((d, &x), &y) in dst.iter_mut().zip(a).zip(b) {
                *d = f(x, y);
            }
        }
        (Values::Lanes(a), Values::Scalar(s)) => {
            for (d, &x) in dst.iter_mut().zip(a) {
                *d = f(x, s);
            }
        }
        (Values::Scalar(s), Values::Lanes(b)) => {
            for (d, &y) in dst.iter_mut().zip(b) {
                *d = f(s, y);
            }
        }
        (Values::Scalar(s), Values::Scalar(t)) => dst.fill(f(s, t)),
    }
}

/// `x^n` for a small integer exponent, as both the tree and the program compute it.
#[inline(always)]
pub(crate) fn powi(x: f64, n: i32) -> f64 {
    if n == 2 { x * x } else { x.powi(n) }
}

impl Program {
    /// Compiles `exprs`; result `k` is expression `k`.
    pub fn compile(exprs: &[&Expr]) -> Program {
        let mut p = Program {
            uniforms: Vec::new(),
            instrs: Vec::new(),
            results: Vec::new(),
        };
        for e in exprs {
            let r = p.operand(e);
            p.results.push(r);
        }
        p
    }

    fn push(&mut self, instr: Instr) -> Operand {
        self.instrs.push(instr);
        Operand::Reg(self.instrs.len() - 1)
    }

    fn operand(&mut self, e: &Expr) -> Operand {
        if !e.uses_state() {
            // identical uniform sub-expressions share a slot
            if let Some(k) = self.uniforms.iter().position(|u| u == e) {
                return Operand::Uniform(k);
            }
            self.uniforms.push(e.clone());
            return Operand::Uniform(self.uniforms.len() - 1);
        }
        match &e.node {
            Node::Var(Var::State(i)) => Operand::State(*i),
            Node::Num(_) | Node::Var(_) => unreachable!("uniform"),
            Node::Neg(a) => {
                let a = self.operand(a);
                self.push(Instr::Neg(a))
            }
            Node::Bin(BinOp::Pow, a, b) if integer_exponent(b).is_some() => {
                let a = self.operand(a);
                self.push(Instr::Powi(a, integer_exponent(b).unwrap_or(1)))
            }
            Node::Bin(op, a, b) => {
                let (a, b) = (self.operand(a), self.operand(b));
                self.push(Instr::Bin(*op, a, b))
            }
            Node::Call(f, args) => match args.as_slice() {
                [a] => {
                    let a = self.operand(a);
                    self.push(Instr::Call1(*f, a))
                }
                [a, b] => {
                    let (a, b) = (self.operand(a), self.operand(b));
                    self.push(Instr::Call2(*f, a, b))
                }
                _ => unreachable!("arity is checked by the parser"),
            },
        }
    }

    /// Number of lane registers.
    pub fn registers(&self) -> usize {
        self.instrs.len()
    }

    /// Evaluates the uniform values for one call into `slots`.
    pub fn uniforms(&self, lookup: &impl Fn(Var) -> f64, slots: &mut Vec<f64>) {
        slots.clear();
        slots.extend(self.uniforms.iter().map(|u| u.eval(lookup)));
    }

    /// Runs the instructions over `lanes` lanes: `states[i]` is the column of state
    /// `i`; `regs` is resized to `registers() * lanes`.
    pub fn run(&self, states: &[&[f64]], lanes: usize, slots: &[f64], regs: &mut Vec<f64>) {
        regs.resize(self.instrs.len() * lanes, 0.0);
        for (k, instr) in self.instrs.iter().enumerate() {
            let (done, rest) = regs.split_at_mut(k * lanes);
            let dst = &mut rest[..lanes];
            let get = |o: Operand| -> Values {
                match o {
                    Operand::State(i) => Values::Lanes(&states[i][..lanes]),
                    Operand::Reg(r) => Values::Lanes(&done[r * lanes..(r + 1) * lanes]),
                    Operand::Uniform(s) => Values::Scalar(slots[s]),
                }
            };
            match *instr {
                Instr::Bin(op, a, b) => {
                    let (a, b) = (get(a), get(b));
                    match op {
                        BinOp::Add => binary(dst, a, b, |x, y| x + y),
                        BinOp::Sub => binary(dst, a, b, |x, y| x - y),
                        BinOp::Mul => binary(dst, a, b, |x, y| x * y),
                        BinOp::Div => binary(dst, a, b, |x, y| x / y),
                        BinOp::Pow => binary(dst, a, b, f64::powf),
                    }
                }
                Instr::Powi(a, n) => match n {
                    2 => unary(dst, get(a), |x| powi(x, 2)),
                    _ => unary(dst, get(a), |x| powi(x, n)),
                },
                Instr::Neg(a) => unary(dst, get(a), |x| -x),
                Instr::Call1(f, a) => match f {
                    Function::Exp => unary(dst, get(a), f64::exp),
                    Function::Sin => unary(dst, get(a), f64::sin),
                    Function::Cos => unary(dst, get(a), f64::cos),
                    Function::Abs => unary(dst, get(a), f64::abs),
                    Function::Sqrt => unary(dst, get(a), f64::sqrt),
                    _ => unary(dst, get(a), |x| f.apply1(x)),
                },
                Instr::Call2(f, a, b) => binary(dst, get(a), get(b), |x, y| f.apply2(x, y)),
            }
        }
    }

    /// The values of result `k` after [`run`](Self::run).
    pub fn result<'a>(
        &self,
        k: usize,
        states: &[&'a [f64]],
        lanes: usize,
        slots: &[f64],
        regs: &'a [f64],
    ) -> Values<'a> {
        match self.results[k] {
            Operand::State(i) => Values::Lanes(&states[i][..lanes]),
            Operand::Reg(r) => Values::Lanes(&regs[r * lanes..(r + 1) * lanes]),
            Operand::Uniform(s) => Values::Scalar(slots[s]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::parse;

    fn names(n: &str) -> Option<Var> {
        match n {
            "x" => Some(Var::State(0)),
            "v" => Some(Var::State(1)),
            "u" => Some(Var::Input(0)),
            "t" => Some(Var::Time),
            "a" => Some(Var::Param(0)),
            _ => None,
        }
    }

    /// Every lane of the compiled program equals the tree's value at that lane, bit
    /// for bit (the scalar paths of the models walk the tree).
    #[test]
    fn the_compiled_program_gives_the_trees_values_bit_for_bit() {
        let texts = [
            "a*x + 25*x/(1 + x^2) + 8*cos(1.2*(t + 1))",
            "0.05*x^2",
            "x + 0.05*v",
            "v - 0.05*(a*sin(x) + 0.5*v) + u",
            "exp(-abs(x)) * max(x, v) - min(x^3, 2) + sqrt(x^2 + v^2) + x^v",
            "tanh(a) + log(1 + x^2) / a - atan(v) + tan(0.1*x)",
            "3",
            "v",
        ];
        let exprs: Vec<Expr> = texts.iter().map(|t| parse(t, &names).unwrap()).collect();
        let program = Program::compile(&exprs.iter().collect::<Vec<_>>());
        let xs = [-3.2, -0.4, 0.0, 0.7, 1.9, 12.5, -25.0];
        let vs = [0.3, -1.0, 2.0, 0.0, 5.5, -0.1, 1.0];
        let (t, u, a) = (7.0, 0.3, 0.5);
        let lookup = |v: Var| match v {
            Var::Time => t,
            Var::Input(_) => u,
            Var::Param(_) => a,
            Var::State(_) => f64::NAN,
        };
        let mut slots = Vec::new();
        program.uniforms(&lookup, &mut slots);
        let mut regs = Vec::new();
        let states = [&xs[..], &vs[..]];
        program.run(&states, xs.len(), &slots, &mut regs);
        for (k, e) in exprs.iter().enumerate() {
            let values = program.result(k, &states, xs.len(), &slots, &regs);
            for lane in 0..xs.len() {
                let tree = e.eval(&|v| match v {
                    Var::State(0) => xs[lane],
                    Var::State(_) => vs[lane],
                    other => lookup(other),
                });
                assert_eq!(
                    values.at(lane).to_bits(),
                    tree.to_bits(),
                    "{} lane {lane}",
                    texts[k]
                );
            }
        }
    }
}
