//! Expressions of a model file: the syntax tree and its parser.
//!
//! # Grammar
//! ```text
//! sum     = product (("+" | "-") product)*
//! product = unary (("*" | "/") unary)*
//! unary   = ("-" | "+") unary | power
//! power   = atom ("^" unary)?            right-associative: 2^3^2 = 2^9; -x^2 = -(x^2)
//! atom    = number | name | name "(" sum ("," sum)* ")" | "(" sum ")"
//! ```
//! Names are states, inputs, parameters, or `t` (the 0-based sample index); functions
//! are those of [`Function`]. Every node keeps its byte span in the expression text, so
//! that errors point at the offending characters.

use std::fmt;

/// What a name refers to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Var {
    /// State `i` (`x_t` in an equation).
    State(usize),
    /// Input `i` (`u_t`).
    Input(usize),
    /// The 0-based sample index `t`.
    Time,
    /// Parameter `i`.
    Param(usize),
}

/// The functions an expression may call.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Function {
    /// `exp(x)`.
    Exp,
    /// Natural logarithm `log(x)`.
    Log,
    /// `sin(x)`.
    Sin,
    /// `cos(x)`.
    Cos,
    /// `tan(x)`.
    Tan,
    /// `atan(x)`.
    Atan,
    /// `tanh(x)`.
    Tanh,
    /// `sqrt(x)`.
    Sqrt,
    /// `abs(x)`.
    Abs,
    /// `min(x, y)`.
    Min,
    /// `max(x, y)`.
    Max,
    /// `sign(x)`: -1, 0 or 1.
    Sign,
}

impl Function {
    /// Every function, for messages.
    pub const ALL: [Function; 12] = [
        Function::Exp,
        Function::Log,
        Function::Sin,
        Function::Cos,
        Function::Tan,
        Function::Atan,
        Function::Tanh,
        Function::Sqrt,
        Function::Abs,
        Function::Min,
        Function::Max,
        Function::Sign,
    ];

    /// The name in expressions.
    pub fn name(self) -> &'static str {
        match self {
            Function::Exp => "exp",
            Function::Log => "log",
            Function::Sin => "sin",
            Function::Cos => "cos",
            Function::Tan => "tan",
            Function::Atan => "atan",
            Function::Tanh => "tanh",
            Function::Sqrt => "sqrt",
            Function::Abs => "abs",
            Function::Min => "min",
            Function::Max => "max",
            Function::Sign => "sign",
        }
    }

    /// The function called `name`.
    pub fn from_name(name: &str) -> Option<Function> {
        Function::ALL.into_iter().find(|f| f.name() == name)
    }

    /// Number of arguments.
    pub fn arity(self) -> usize {
        match self {
            Function::Min | Function::Max => 2,
            _ => 1,
        }
    }

    /// The function of one argument at `x` (`min`/`max` take [`apply2`](Self::apply2)).
    #[inline(always)]
    pub fn apply1(self, x: f64) -> f64 {
        match self {
            Function::Exp => x.exp(),
            Function::Log => x.ln(),
            Function::Sin => x.sin(),
            Function::Cos => x.cos(),
            Function::Tan => x.tan(),
            Function::Atan => x.atan(),
            Function::Tanh => x.tanh(),
            Function::Sqrt => x.sqrt(),
            Function::Abs => x.abs(),
            Function::Sign => {
                if x > 0.0 {
                    1.0
                } else if x < 0.0 {
                    -1.0
                } else {
                    x // 0, -0 or NaN
                }
            }
            Function::Min | Function::Max => f64::NAN,
        }
    }

    /// The function of two arguments.
    #[inline(always)]
    pub fn apply2(self, x: f64, y: f64) -> f64 {
        match self {
            Function::Min => x.min(y),
            Function::Max => x.max(y),
            _ => f64::NAN,
        }
    }
}

/// A binary operator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BinOp {
    /// `+`.
    Add,
    /// `-`.
    Sub,
    /// `*`.
    Mul,
    /// `/`.
    Div,
    /// `^`.
    Pow,
}

impl BinOp {
    /// `a op b`.
    #[inline(always)]
    pub fn apply(self, a: f64, b: f64) -> f64 {
        match self {
            BinOp::Add => a + b,
            BinOp::Sub => a - b,
            BinOp::Mul => a * b,
            BinOp::Div => a / b,
            BinOp::Pow => a.powf(b),
        }
    }

    fn symbol(self) -> char {
        match self {
            BinOp::Add => '+',
            BinOp::Sub => '-',
            BinOp::Mul => '*',
            BinOp::Div => '/',
            BinOp::Pow => '^',
        }
    }
}

/// A node of the syntax tree.
#[derive(Debug, Clone, PartialEq)]
pub enum Node {
    /// A number.
    Num(f64),
    /// A state, input, parameter or the time.
    Var(Var),
    /// `-a`.
    Neg(Box<Expr>),
    /// `a op b`.
    Bin(BinOp, Box<Expr>, Box<Expr>),
    /// `f(args)`.
    Call(Function, Vec<Expr>),
}

/// An expression with the byte span `[start, end)` of its text.
#[derive(Debug, Clone, PartialEq)]
pub struct Expr {
    /// The node.
    pub node: Node,
    /// Byte offsets in the expression's text.
    pub span: (usize, usize),
}

impl Expr {
    /// A number without a place in a text (built by sysid, not parsed).
    pub fn num(v: f64) -> Expr {
        Expr {
            node: Node::Num(v),
            span: (0, 0),
        }
    }

    /// `a op b`, spanning both.
    pub fn bin(op: BinOp, a: Expr, b: Expr) -> Expr {
        let span = (a.span.0.min(b.span.0), a.span.1.max(b.span.1));
        Expr {
            node: Node::Bin(op, Box::new(a), Box::new(b)),
            span,
        }
    }

    /// `-a`.
    pub fn negated(a: Expr) -> Expr {
        let span = a.span;
        Expr {
            node: Node::Neg(Box::new(a)),
            span,
        }
    }

    /// Whether any sub-expression satisfies `pred`.
    pub fn any(&self, pred: &impl Fn(&Expr) -> bool) -> bool {
        if pred(self) {
            return true;
        }
        match &self.node {
            Node::Num(_) | Node::Var(_) => false,
            Node::Neg(a) => a.any(pred),
            Node::Bin(_, a, b) => a.any(pred) || b.any(pred),
            Node::Call(_, args) => args.iter().any(|a| a.any(pred)),
        }
    }

    /// Whether the expression mentions `var`.
    pub fn uses(&self, var: Var) -> bool {
        self.any(&|e| e.node == Node::Var(var))
    }

    /// Whether the expression depends on a state.
    pub fn uses_state(&self) -> bool {
        self.any(&|e| matches!(e.node, Node::Var(Var::State(_))))
    }

    /// The value with `lookup` giving each variable.
    pub fn eval(&self, lookup: &impl Fn(Var) -> f64) -> f64 {
        match &self.node {
            Node::Num(v) => *v,
            Node::Var(v) => lookup(*v),
            Node::Neg(a) => -a.eval(lookup),
            Node::Bin(BinOp::Pow, a, b) if crate::program::integer_exponent(b).is_some() => {
                let n = crate::program::integer_exponent(b).unwrap_or(1);
                crate::program::powi(a.eval(lookup), n)
            }
            Node::Bin(op, a, b) => op.apply(a.eval(lookup), b.eval(lookup)),
            Node::Call(f, args) => match args.as_slice() {
                [a] => f.apply1(a.eval(lookup)),
                [a, b] => f.apply2(a.eval(lookup), b.eval(lookup)),
                _ => f64::NAN,
            },
        }
    }

    /// The first sub-expression (in evaluation order) whose value under `lookup` is
    /// not finite although its operands are: where a NaN or an infinity is born.
    pub fn first_non_finite(&self, lookup: &impl Fn(Var) -> f64) -> Option<&Expr> {
        let children: Vec<&Expr> = match &self.node {
            Node::Num(_) | Node::Var(_) => vec![],
            Node::Neg(a) => vec![a],
            Node::Bin(_, a, b) => vec![a, b],
            Node::Call(_, args) => args.iter().collect(),
        };
        for c in children {
            if let Some(e) = c.first_non_finite(lookup) {
                return Some(e);
            }
        }
        (!self.eval(lookup).is_finite()).then_some(self)
    }

    /// The expression as text, with `name` naming the variables (fully parenthesised
    /// where precedence needs it).
    pub fn display<'a>(&'a self, name: &'a dyn Fn(Var) -> String) -> impl fmt::Display + 'a {
        Shown { expr: self, name }
    }
}

fn is_num(e: &Expr, v: f64) -> bool {
    matches!(e.node, Node::Num(x) if x == v)
}

fn sum(a: Expr, b: Expr) -> Expr {
    if is_num(&a, 0.0) {
        b
    } else if is_num(&b, 0.0) {
        a
    } else {
        Expr::bin(BinOp::Add, a, b)
    }
}

fn difference(a: Expr, b: Expr) -> Expr {
    if is_num(&b, 0.0) {
        a
    } else if is_num(&a, 0.0) {
        Expr::negated(b)
    } else {
        Expr::bin(BinOp::Sub, a, b)
    }
}

fn product(a: Expr, b: Expr) -> Expr {
    if is_num(&a, 0.0) || is_num(&b, 0.0) {
        Expr::num(0.0)
    } else if is_num(&a, 1.0) {
        b
    } else if is_num(&b, 1.0) {
        a
    } else {
        Expr::bin(BinOp::Mul, a, b)
    }
}

fn quotient(a: Expr, b: Expr) -> Expr {
    if is_num(&a, 0.0) {
        Expr::num(0.0)
    } else if is_num(&b, 1.0) {
        a
    } else {
        Expr::bin(BinOp::Div, a, b)
    }
}

fn call(f: Function, args: Vec<Expr>) -> Expr {
    Expr {
        node: Node::Call(f, args),
        span: (0, 0),
    }
}

impl Expr {
    /// The symbolic derivative with respect to `var` (zeros and ones folded). Where
    /// the function has a kink (`abs`, `min`, `max` at a tie, `sign`), the derivative
    /// is that of either side's average (0 for `sign`).
    pub fn derivative(&self, var: Var) -> Expr {
        match &self.node {
            Node::Num(_) => Expr::num(0.0),
            Node::Var(v) => Expr::num(if *v == var { 1.0 } else { 0.0 }),
            Node::Neg(a) => {
                let da = a.derivative(var);
                if is_num(&da, 0.0) {
                    da
                } else {
                    Expr::negated(da)
                }
            }
            Node::Bin(op, a, b) => {
                let (da, db) = (a.derivative(var), b.derivative(var));
                let (a, b) = ((**a).clone(), (**b).clone());
                match op {
                    BinOp::Add => sum(da, db),
                    BinOp::Sub => difference(da, db),
                    BinOp::Mul => sum(product(da, b), product(a, db)),
                    // a'/b - a b' / b^2
                    BinOp::Div => difference(
                        quotient(da, b.clone()),
                        quotient(product(a, db), Expr::bin(BinOp::Pow, b, Expr::num(2.0))),
                    ),
                    BinOp::Pow if is_num(&db, 0.0) => {
                        // b a^(b - 1) a'
                        let lowered = match b.node {
                            Node::Num(v) => Expr::num(v - 1.0),
                            _ => Expr::bin(BinOp::Sub, b.clone(), Expr::num(1.0)),
                        };
                        let power = if is_num(&lowered, 1.0) {
                            a.clone()
                        } else {
                            Expr::bin(BinOp::Pow, a.clone(), lowered)
                        };
                        product(product(b, power), da)
                    }
                    // a^b (b' ln a + b a' / a)
                    BinOp::Pow => product(
                        Expr::bin(BinOp::Pow, a.clone(), b.clone()),
                        sum(
                            product(db, call(Function::Log, vec![a.clone()])),
                            quotient(product(b, da), a),
                        ),
                    ),
                }
            }
            Node::Call(f, args) => {
                let a = args[0].clone();
                let da = a.derivative(var);
                match f {
                    Function::Min | Function::Max => {
                        let b = args[1].clone();
                        let db = b.derivative(var);
                        if is_num(&da, 0.0) && is_num(&db, 0.0) {
                            return Expr::num(0.0);
                        }
                        // (a' + b')/2 +- (a' - b')/2 sign(a - b)
                        let half = |e: Expr| quotient(e, Expr::num(2.0));
                        let mean = half(sum(da.clone(), db.clone()));
                        let spread = half(difference(da, db));
                        let side = call(Function::Sign, vec![Expr::bin(BinOp::Sub, a, b)]);
                        if *f == Function::Max {
                            sum(mean, product(spread, side))
                        } else {
                            difference(mean, product(spread, side))
                        }
                    }
                    _ if is_num(&da, 0.0) => Expr::num(0.0),
                    Function::Exp => product(self.clone(), da),
                    Function::Log => quotient(da, a),
                    Function::Sin => product(call(Function::Cos, vec![a]), da),
                    Function::Cos => Expr::negated(product(call(Function::Sin, vec![a]), da)),
                    // a' (1 + tan^2)
                    Function::Tan => product(
                        da,
                        sum(
                            Expr::num(1.0),
                            Expr::bin(BinOp::Pow, self.clone(), Expr::num(2.0)),
                        ),
                    ),
                    Function::Atan => quotient(
                        da,
                        sum(Expr::num(1.0), Expr::bin(BinOp::Pow, a, Expr::num(2.0))),
                    ),
                    Function::Tanh => product(
                        da,
                        difference(
                            Expr::num(1.0),
                            Expr::bin(BinOp::Pow, self.clone(), Expr::num(2.0)),
                        ),
                    ),
                    Function::Sqrt => quotient(da, product(Expr::num(2.0), self.clone())),
                    Function::Abs => product(da, call(Function::Sign, vec![a])),
                    Function::Sign => Expr::num(0.0),
                }
            }
        }
    }
}

struct Shown<'a> {
    expr: &'a Expr,
    name: &'a dyn Fn(Var) -> String,
}

fn precedence(node: &Node) -> u8 {
    match node {
        Node::Bin(BinOp::Add | BinOp::Sub, ..) => 1,
        Node::Bin(BinOp::Mul | BinOp::Div, ..) => 2,
        Node::Neg(_) => 3,
        Node::Bin(BinOp::Pow, ..) => 4,
        Node::Num(v) if *v < 0.0 => 3,
        _ => 5,
    }
}

impl fmt::Display for Shown<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let sub = |e: &Expr, f: &mut fmt::Formatter<'_>, min: u8| -> fmt::Result {
            let shown = Shown {
                expr: e,
                name: self.name,
            };
            if precedence(&e.node) < min {
                write!(f, "({shown})")
            } else {
                write!(f, "{shown}")
            }
        };
        match &self.expr.node {
            // integers as integers; else the shortest text that reads back to the bits
            Node::Num(v) if v.fract() == 0.0 && v.abs() < 1e15 => write!(f, "{}", *v as i64),
            Node::Num(v) => write!(f, "{v:?}"),
            Node::Var(v) => write!(f, "{}", (self.name)(*v)),
            Node::Neg(a) => {
                write!(f, "-")?;
                sub(a, f, 4)
            }
            Node::Bin(op, a, b) => {
                let p = precedence(&self.expr.node);
                // left-associative + - * /: the right operand needs a higher level;
                // right-associative ^: the left one does
                let (left, right) = if *op == BinOp::Pow {
                    (p + 1, p)
                } else {
                    (p, p + 1)
                };
                sub(a, f, left)?;
                if p == 1 {
                    write!(f, " {} ", op.symbol())?;
                } else {
                    write!(f, "{}", op.symbol())?;
                }
                sub(b, f, right)
            }
            Node::Call(fun, args) => {
                write!(f, "{}(", fun.name())?;
                for (k, a) in args.iter().enumerate() {
                    if k > 0 {
                        write!(f, ", ")?;
                    }
                    sub(a, f, 0)?;
                }
                write!(f, ")")
            }
        }
    }
}

/// Why an expression could not be parsed, with the byte span it concerns.
#[derive(Debug, Clone, PartialEq)]
pub struct ParseError {
    /// What is wrong.
    pub message: String,
    /// Byte offsets in the expression's text.
    pub span: (usize, usize),
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Token<'a> {
    Num(f64),
    Name(&'a str),
    Op(char),
    End,
}

struct Lexer<'a> {
    text: &'a str,
    pos: usize,
}

impl<'a> Lexer<'a> {
    fn skip_space(&mut self) {
        let rest = &self.text[self.pos..];
        self.pos += rest.len() - rest.trim_start().len();
    }

    /// The next token and its span, without consuming it.
    fn peek(&mut self) -> Result<(Token<'a>, (usize, usize)), ParseError> {
        self.skip_space();
        let start = self.pos;
        let rest = &self.text[start..];
        let Some(c) = rest.chars().next() else {
            return Ok((Token::End, (start, start)));
        };
        if c.is_ascii_digit() || (c == '.' && rest[1..].starts_with(|d: char| d.is_ascii_digit())) {
            let mut end = 0;
            let bytes = rest.as_bytes();
            while end < bytes.len() && (bytes[end].is_ascii_digit() || bytes[end] == b'.') {
                end += 1;
            }
            if end < bytes.len() && (bytes[end] == b'e' || bytes[end] == b'E') {
                let mut k = end + 1;
                if k < bytes.len() && (bytes[k] == b'+' || bytes[k] == b'-') {
                    k += 1;
                }
                if k < bytes.len() && bytes[k].is_ascii_digit() {
                    while k < bytes.len() && bytes[k].is_ascii_digit() {
                        k += 1;
                    }
                    end = k;
                }
            }
            let span = (start, start + end);
            return match rest[..end].parse::<f64>() {
                Ok(v) if v.is_finite() => Ok((Token::Num(v), span)),
                _ => Err(ParseError {
                    message: format!("malformed number {:?}", &rest[..end]),
                    span,
                }),
            };
        }
        if c.is_ascii_alphabetic() || c == '_' {
            let end = rest
                .find(|d: char| !(d.is_ascii_alphanumeric() || d == '_'))
                .unwrap_or(rest.len());
            return Ok((Token::Name(&rest[..end]), (start, start + end)));
        }
        if "+-*/^(),".contains(c) {
            return Ok((Token::Op(c), (start, start + 1)));
        }
        Err(ParseError {
            message: format!("unexpected character {c:?}"),
            span: (start, start + c.len_utf8()),
        })
    }

    fn next(&mut self) -> Result<(Token<'a>, (usize, usize)), ParseError> {
        let (token, span) = self.peek()?;
        self.pos = span.1;
        Ok((token, span))
    }
}

/// Deepest nesting an expression may have (the parser and every pass over the tree
/// recurse; a file of 100 000 parentheses must not overflow the stack).
pub const MAX_DEPTH: usize = 200;

/// Most operations of sums and products (`a + b - c`, `a*b/c`) on any path into an
/// expression, nesting included. A chain of `+` is a tree as deep as it is long, which
/// every pass over the tree recurses through: a sum of 70 000 terms overflowed the
/// stack, where the nesting check, which counts parentheses, saw nothing.
pub const MAX_CHAIN: usize = 1000;

/// Stack a thread needs to parse, differentiate and evaluate the deepest expression
/// allowed ([`MAX_DEPTH`], [`MAX_CHAIN`]) by the tree's recursive passes: measured
/// between 1 and 2 MiB in a release build (1 MiB overflows), 1 MiB in the tests'
/// profile; this has a margin of 8. Rust's spawned threads and rayon's workers get
/// 2 MiB by default, so `sysid` and the Python package build their rayon pools with
/// this much; a program that evaluates model files on its own threads should too.
pub const STACK_BYTES: usize = 16 << 20;

struct Parser<'a, 'n> {
    lexer: Lexer<'a>,
    names: &'n dyn Fn(&str) -> Option<Var>,
    depth: usize,
    /// Operations of the sums and products enclosing the point being parsed.
    chain: usize,
}

/// Parses `text`, resolving names with `names` (`None`: unknown).
pub fn parse(text: &str, names: &dyn Fn(&str) -> Option<Var>) -> Result<Expr, ParseError> {
    let mut p = Parser {
        lexer: Lexer { text, pos: 0 },
        names,
        depth: 0,
        chain: 0,
    };
    let e = p.sum()?;
    match p.lexer.next()? {
        (Token::End, _) => Ok(e),
        (Token::Op(')'), span) => Err(ParseError {
            message: "unmatched ')'".into(),
            span,
        }),
        (_, span) => Err(ParseError {
            message: "expected an operator (+ - * / ^) or the end of the expression".into(),
            span,
        }),
    }
}

impl Parser<'_, '_> {
    fn enter(&mut self, span: (usize, usize)) -> Result<(), ParseError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(ParseError {
                message: format!("nested more than {MAX_DEPTH} levels deep"),
                span,
            });
        }
        Ok(())
    }

    /// One more operation of a sum or product on the current path.
    fn extend_chain(&mut self, span: (usize, usize)) -> Result<(), ParseError> {
        self.chain += 1;
        if self.chain > MAX_CHAIN {
            return Err(ParseError {
                message: format!(
                    "more than {MAX_CHAIN} operations of sums and products in one expression \
                     (or nested in one another): split it into named intermediate terms"
                ),
                span,
            });
        }
        Ok(())
    }

    fn sum(&mut self) -> Result<Expr, ParseError> {
        let mut e = self.product()?;
        let outer = self.chain;
        while let (Token::Op(c @ ('+' | '-')), span) = self.lexer.peek()? {
            self.lexer.next()?;
            self.extend_chain(span)?;
            let op = if c == '+' { BinOp::Add } else { BinOp::Sub };
            e = Expr::bin(op, e, self.product()?);
        }
        self.chain = outer;
        Ok(e)
    }

    fn product(&mut self) -> Result<Expr, ParseError> {
        let mut e = self.unary()?;
        let outer = self.chain;
        while let (Token::Op(c @ ('*' | '/')), span) = self.lexer.peek()? {
            self.lexer.next()?;
            self.extend_chain(span)?;
            let op = if c == '*' { BinOp::Mul } else { BinOp::Div };
            e = Expr::bin(op, e, self.unary()?);
        }
        self.chain = outer;
        Ok(e)
    }

    fn unary(&mut self) -> Result<Expr, ParseError> {
        let (token, span) = self.lexer.peek()?;
        match token {
            Token::Op(c @ ('-' | '+')) => {
                self.lexer.next()?;
                self.enter(span)?;
                let inner = self.unary()?;
                self.depth -= 1;
                let span = (span.0, inner.span.1);
                Ok(if c == '-' {
                    Expr {
                        node: Node::Neg(Box::new(inner)),
                        span,
                    }
                } else {
                    Expr { span, ..inner }
                })
            }
            _ => self.power(),
        }
    }

    fn power(&mut self) -> Result<Expr, ParseError> {
        let base = self.atom()?;
        if let (Token::Op('^'), span) = self.lexer.peek()? {
            self.lexer.next()?;
            self.enter(span)?;
            let exponent = self.unary()?;
            self.depth -= 1;
            return Ok(Expr::bin(BinOp::Pow, base, exponent));
        }
        Ok(base)
    }

    fn atom(&mut self) -> Result<Expr, ParseError> {
        let (token, span) = self.lexer.next()?;
        match token {
            Token::Num(v) => Ok(Expr {
                node: Node::Num(v),
                span,
            }),
            Token::Name(name) => {
                if let (Token::Op('('), _) = self.lexer.peek()? {
                    return self.call(name, span);
                }
                if let Some(var) = (self.names)(name) {
                    return Ok(Expr {
                        node: Node::Var(var),
                        span,
                    });
                }
                let message = if Function::from_name(name).is_some() {
                    format!("function {name} needs its arguments: {name}(...)")
                } else {
                    format!("unknown name {name:?}")
                };
                Err(ParseError { message, span })
            }
            Token::Op('(') => {
                self.enter(span)?;
                let inner = self.sum()?;
                self.depth -= 1;
                match self.lexer.next()? {
                    (Token::Op(')'), close) => Ok(Expr {
                        span: (span.0, close.1),
                        ..inner
                    }),
                    (_, at) => Err(ParseError {
                        message: "expected ')' to close the '(' here".into(),
                        span: (span.0, at.1.max(span.1)),
                    }),
                }
            }
            Token::End => Err(ParseError {
                message: if span.0 == 0 {
                    "empty expression".into()
                } else {
                    "the expression ends where a value was expected".into()
                },
                span,
            }),
            Token::Op(c) => Err(ParseError {
                message: format!("expected a number, a name or '(' before {c:?}"),
                span,
            }),
        }
    }

    fn call(&mut self, name: &str, name_span: (usize, usize)) -> Result<Expr, ParseError> {
        let Some(function) = Function::from_name(name) else {
            return Err(ParseError {
                message: format!(
                    "unknown function {name:?} (known: {})",
                    Function::ALL.map(Function::name).join(", ")
                ),
                span: name_span,
            });
        };
        self.lexer.next()?; // '('
        self.enter(name_span)?;
        let mut args = vec![self.sum()?];
        let close = loop {
            match self.lexer.next()? {
                (Token::Op(','), _) => args.push(self.sum()?),
                (Token::Op(')'), span) => break span,
                (_, span) => {
                    return Err(ParseError {
                        message: format!("expected ',' or ')' in the arguments of {name}"),
                        span,
                    });
                }
            }
        };
        self.depth -= 1;
        let span = (name_span.0, close.1);
        if args.len() != function.arity() {
            return Err(ParseError {
                message: format!(
                    "{name} takes {} argument{}, not {}",
                    function.arity(),
                    if function.arity() == 1 { "" } else { "s" },
                    args.len()
                ),
                span,
            });
        }
        Ok(Expr {
            node: Node::Call(function, args),
            span,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: &str) -> Option<Var> {
        match n {
            "x" => Some(Var::State(0)),
            "v" => Some(Var::State(1)),
            "u" => Some(Var::Input(0)),
            "t" => Some(Var::Time),
            "a" => Some(Var::Param(0)),
            "b" => Some(Var::Param(1)),
            _ => None,
        }
    }

    fn value(text: &str) -> f64 {
        let e = parse(text, &names).unwrap_or_else(|e| panic!("{text}: {e:?}"));
        e.eval(&|v| match v {
            Var::State(0) => 2.0,
            Var::State(_) => -1.5,
            Var::Input(_) => 0.25,
            Var::Time => 3.0,
            Var::Param(0) => 0.5,
            Var::Param(_) => 25.0,
        })
    }

    #[test]
    fn precedence_and_associativity_follow_the_usual_rules() {
        let cases: [(&str, f64); 14] = [
            ("1 + 2 * 3", 7.0),
            ("(1 + 2) * 3", 9.0),
            ("2 ^ 3 ^ 2", 512.0),
            ("-x^2", -4.0),
            ("(-x)^2", 4.0),
            ("x - v - 1", 2.0 + 1.5 - 1.0),
            ("x / 4 / 2", 0.25),
            (
                "a*x + b*x/(1 + x^2) + 8*cos(1.2*(t + 1))",
                1.0 + 10.0 + 8.0 * 4.8f64.cos(),
            ),
            ("min(x, v) + max(x, v)", 0.5),
            ("exp(log(3))", 3.0_f64.ln().exp()),
            ("2.5e-1 + .5 + 1E1", 10.75),
            ("- - x", 2.0),
            ("sqrt(abs(v)) * tanh(u)", 1.5f64.sqrt() * 0.25f64.tanh()),
            ("x*-1", -2.0),
        ];
        for (text, expected) in cases {
            assert_eq!(value(text), expected, "{text}");
        }
    }

    #[test]
    fn errors_point_at_the_offending_characters() {
        let cases: [(&str, &str, (usize, usize)); 11] = [
            ("a*z", "unknown name \"z\"", (2, 3)),
            ("sinh(x)", "unknown function \"sinh\"", (0, 4)),
            ("min(x)", "min takes 2 arguments, not 1", (0, 6)),
            ("cos(x, v)", "cos takes 1 argument, not 2", (0, 9)),
            ("(x + 1", "expected ')'", (0, 6)),
            ("x + 1)", "unmatched ')'", (5, 6)),
            ("x +", "ends where a value was expected", (3, 3)),
            ("", "empty expression", (0, 0)),
            ("x $ 2", "unexpected character '$'", (2, 3)),
            ("x 2", "expected an operator", (2, 3)),
            ("exp + 1", "function exp needs its arguments", (0, 3)),
        ];
        for (text, message, span) in cases {
            let e = parse(text, &names).unwrap_err();
            assert!(e.message.contains(message), "{text}: {}", e.message);
            assert_eq!(e.span, span, "{text}: {}", e.message);
        }
    }

    #[test]
    fn deep_nesting_is_an_error_not_a_stack_overflow() {
        let text = format!("{}x{}", "(".repeat(100_000), ")".repeat(100_000));
        let e = parse(&text, &names).unwrap_err();
        assert!(e.message.contains("nested more than"), "{}", e.message);
        let minus = format!("{}x", "-".repeat(100_000));
        assert!(parse(&minus, &names).is_err());
    }

    /// A long sum is a deep tree: 70 000 terms overflowed the stack of every later
    /// pass; it is refused, and the deepest expression allowed (a sum of 1000 products
    /// inside 199 parentheses) parses, evaluates and differentiates on a thread with
    /// an eighth of [`STACK_BYTES`] (2 MiB, where a release build needs between 1 and 2
    /// MiB and this profile 1).
    #[test]
    fn a_long_chain_of_operations_is_an_error_not_a_stack_overflow() {
        let long = vec!["a*x"; 70_000].join(" + ");
        let e = parse(&long, &names).unwrap_err();
        assert!(
            e.message.contains("more than 1000 operations"),
            "{}",
            e.message
        );
        // chains count together through the nesting: 199 levels (under the nesting
        // limit) of six additions each
        let nested = format!(
            "{}x{}",
            "(x + x + x + x + x + x + ".repeat(199),
            ")".repeat(199)
        );
        let e = parse(&nested, &names).unwrap_err();
        assert!(
            e.message.contains("more than 1000 operations"),
            "{}",
            e.message
        );
        // the longest chain allowed, at the deepest nesting allowed
        let fine = format!(
            "{}{}{}",
            "(".repeat(199),
            vec!["a*x"; 1000].join(" + "),
            ")".repeat(199)
        );
        std::thread::Builder::new()
            .stack_size(STACK_BYTES / 8)
            .spawn(move || {
                let e = parse(&fine, &names).unwrap();
                let lookup = |v: Var| match v {
                    Var::Param(_) => 2.0,
                    _ => 0.5,
                };
                assert_eq!(e.eval(&lookup), 1000.0);
                let d = e.derivative(Var::Param(0));
                assert_eq!(d.eval(&lookup), 0.5 * 1000.0);
            })
            .unwrap()
            .join()
            .unwrap();
    }

    /// Each symbolic derivative equals a central difference of the expression (step
    /// 1e-6, agreement to 1e-6 relative), at points away from the kinks.
    #[test]
    fn symbolic_derivatives_match_central_differences() {
        let texts = [
            "a*x + b*x/(1 + x^2) + 8*cos(1.2*(t + 1))",
            "-2*a*b*v - b^2*sin(x) + a/b",
            "exp(a*x) - log(1 + a^2) + sqrt(b) * tanh(a - x)",
            "x^a + a^x + atan(a*b) - tan(0.1*a)",
            "abs(a - 3) + min(a, b) * max(a*x, v) - sign(a)",
            "(a + 1)^3 / (b - a^2)",
        ];
        for text in texts {
            let e = parse(text, &names).unwrap();
            for (var, at) in [(Var::Param(0), 0.7), (Var::Param(1), 2.3)] {
                let d = e.derivative(var);
                let value = |h: f64| {
                    e.eval(&|v| match v {
                        Var::State(0) => 1.3,
                        Var::State(_) => -0.4,
                        Var::Input(_) => 0.25,
                        Var::Time => 3.0,
                        Var::Param(0) => {
                            if var == Var::Param(0) {
                                at + h
                            } else {
                                0.7
                            }
                        }
                        Var::Param(_) => {
                            if var == Var::Param(1) {
                                at + h
                            } else {
                                2.3
                            }
                        }
                    })
                };
                let numeric = (value(1e-6) - value(-1e-6)) / 2e-6;
                let exact = d.eval(&|v| match v {
                    Var::State(0) => 1.3,
                    Var::State(_) => -0.4,
                    Var::Input(_) => 0.25,
                    Var::Time => 3.0,
                    Var::Param(0) => 0.7,
                    Var::Param(_) => 2.3,
                });
                assert!(
                    (exact - numeric).abs() <= 1e-6 * (1.0 + numeric.abs()),
                    "d/d{var:?} {text}: {exact} vs {numeric}"
                );
            }
        }
    }

    #[test]
    fn display_parses_back_to_the_same_value() {
        let show = |v: Var| match v {
            Var::State(0) => "x".to_string(),
            Var::State(_) => "v".into(),
            Var::Input(_) => "u".into(),
            Var::Time => "t".into(),
            Var::Param(0) => "a".into(),
            Var::Param(_) => "b".into(),
        };
        for text in [
            "x - (v - 1)",
            "2^(3^2)",
            "(2^3)^2",
            "-x^2",
            "a/(b*x)",
            "max(x, -v)",
        ] {
            let e = parse(text, &names).unwrap();
            let again = e.display(&show).to_string();
            assert_eq!(value(&again), value(text), "{text} -> {again}");
        }
    }
}
