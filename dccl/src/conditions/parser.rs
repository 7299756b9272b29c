//! The part of Lua 5.3 that condition scripts are written in, parsed into a
//! tree: expressions with every operator at Lua's precedence, calls of the
//! supported library functions, and the statements `local`, assignment to
//! a local, a call, `if`/`elseif`/`else`, `do ... end` and `return`.
//! Loops, function definitions, table constructors, assignments to globals
//! and the library functions not listed in the evaluator (`print`, `tostring`, `tonumber`, `type`, `math`, `string`) are refused here,
//! each by name, before any message is coded.

use std::sync::Arc;

use super::lexer::{tokens, Tok};

/// Binary operators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum BinOp {
    Add,
    Sub,
    Mul,
    Div,
    IDiv,
    Mod,
    Pow,
    Concat,
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
    BAnd,
    BOr,
    BXor,
    Shl,
    Shr,
}

/// Unary operators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum UnOp {
    Neg,
    Not,
    Len,
    BNot,
}

/// The members of `math` supported.
pub(crate) const MATH: &[&str] = &[
    "abs",
    "ceil",
    "floor",
    "fmod",
    "huge",
    "max",
    "min",
    "maxinteger",
    "mininteger",
    "pi",
    "sqrt",
    "tointeger",
    "type",
];

/// The members of `string` supported (also as methods of strings).
pub(crate) const STRING: &[&str] = &["len", "lower", "sub", "upper"];

/// Lua's other standard globals: named in a script, they are refused.
const UNSUPPORTED: &[&str] = &[
    "assert",
    "collectgarbage",
    "dofile",
    "error",
    "getmetatable",
    "ipairs",
    "load",
    "loadfile",
    "loadstring",
    "next",
    "pairs",
    "pcall",
    "rawequal",
    "rawget",
    "rawlen",
    "rawset",
    "require",
    "select",
    "setmetatable",
    "unpack",
    "xpcall",
    "_G",
    "_ENV",
    "_VERSION",
    "bit32",
    "coroutine",
    "debug",
    "io",
    "os",
    "package",
    "table",
    "utf8",
    "pb",
];

/// An expression.
#[derive(Debug, Clone)]
pub(crate) enum Expr {
    Nil,
    Bool(bool),
    Int(i64),
    Num(f64),
    Str(Arc<[u8]>),
    /// `this`, `root`, `this_index`, a library name, or another global (nil).
    Global(Arc<str>),
    /// A local variable, by slot.
    Local(usize, Arc<str>),
    Index(Box<Expr>, Box<Expr>),
    Call(Box<Expr>, Vec<Expr>),
    /// `object:method(args)`.
    Method(Box<Expr>, Arc<str>, Vec<Expr>),
    Bin(BinOp, Box<Expr>, Box<Expr>),
    Un(UnOp, Box<Expr>),
    And(Box<Expr>, Box<Expr>),
    Or(Box<Expr>, Box<Expr>),
    /// A parenthesized expression (one value).
    Paren(Box<Expr>),
}

/// A statement.
#[derive(Debug, Clone)]
pub(crate) enum Stat {
    /// `local a, b = e1, e2` (slots).
    Local(Vec<usize>, Vec<Expr>),
    /// `a = e` for a local `a`.
    Assign(usize, Expr),
    /// A call whose values are dropped.
    Call(Expr),
    /// `if c then ... elseif ... else ... end`.
    If(Vec<(Expr, Vec<Stat>)>, Option<Vec<Stat>>),
    /// `do ... end`.
    Do(Vec<Stat>),
    /// `return e1, e2`.
    Return(Vec<Expr>),
}

/// A parsed script: its statements and the number of local slots.
#[derive(Debug, Clone)]
pub(crate) struct Chunk {
    pub body: Vec<Stat>,
    pub slots: usize,
}

/// Parses a script as libdccl runs it: a script without the word `return`
/// anywhere is an expression (libdccl puts `return ` before it).
pub(crate) fn parse_script(script: &str) -> Result<Chunk, String> {
    let src = if script.contains("return") {
        script.to_string()
    } else {
        format!("return {script}")
    };
    let mut p = Parser {
        toks: tokens(&src)?,
        pos: 0,
        scopes: vec![Vec::new()],
        slots: 0,
    };
    let body = p.block()?;
    if p.peek() != &Tok::Eof {
        return Err(format!("'<eof>' expected near {}", p.describe()));
    }
    Ok(Chunk {
        body,
        slots: p.slots,
    })
}

struct Parser {
    toks: Vec<Tok>,
    pos: usize,
    /// Local names in scope, innermost block last: `(name, slot)`.
    scopes: Vec<Vec<(Arc<str>, usize)>>,
    slots: usize,
}

fn is_keyword(name: &str) -> bool {
    matches!(
        name,
        "and"
            | "break"
            | "do"
            | "else"
            | "elseif"
            | "end"
            | "false"
            | "for"
            | "function"
            | "goto"
            | "if"
            | "in"
            | "local"
            | "nil"
            | "not"
            | "or"
            | "repeat"
            | "return"
            | "then"
            | "true"
            | "until"
            | "while"
    )
}

impl Parser {
    fn peek(&self) -> &Tok {
        &self.toks[self.pos]
    }

    fn next(&mut self) -> Tok {
        let t = self.toks[self.pos].clone();
        if self.pos + 1 < self.toks.len() {
            self.pos += 1;
        }
        t
    }

    fn describe(&self) -> String {
        match self.peek() {
            Tok::Name(n) => format!("'{n}'"),
            Tok::Str(s) => format!("'{}'", String::from_utf8_lossy(s)),
            Tok::Int(i) => format!("'{i}'"),
            Tok::Num(f) => format!("'{f}'"),
            Tok::Op(o) => format!("'{o}'"),
            Tok::Eof => "<eof>".to_string(),
        }
    }

    fn is_op(&self, op: &str) -> bool {
        matches!(self.peek(), Tok::Op(o) if *o == op)
    }

    fn is_kw(&self, kw: &str) -> bool {
        matches!(self.peek(), Tok::Name(n) if &**n == kw)
    }

    fn expect_op(&mut self, op: &str) -> Result<(), String> {
        if self.is_op(op) {
            self.next();
            Ok(())
        } else {
            Err(format!("'{op}' expected near {}", self.describe()))
        }
    }

    fn expect_kw(&mut self, kw: &str) -> Result<(), String> {
        if self.is_kw(kw) {
            self.next();
            Ok(())
        } else {
            Err(format!("'{kw}' expected near {}", self.describe()))
        }
    }

    fn name(&mut self) -> Result<Arc<str>, String> {
        match self.peek().clone() {
            Tok::Name(n) if !is_keyword(&n) => {
                self.next();
                Ok(n)
            }
            Tok::Name(n) if matches!(&*n, "while" | "for" | "repeat" | "goto" | "break") => Err(
                format!("'{n}' is not supported in DCCL conditions (no loops)"),
            ),
            Tok::Name(n) if &*n == "function" => {
                Err("function definitions are not supported in DCCL conditions".into())
            }
            _ => Err(format!("unexpected symbol near {}", self.describe())),
        }
    }

    fn local(&self, name: &str) -> Option<usize> {
        self.scopes
            .iter()
            .rev()
            .flat_map(|s| s.iter().rev())
            .find(|(n, _)| &**n == name)
            .map(|(_, slot)| *slot)
    }

    fn block_ends(&self) -> bool {
        self.peek() == &Tok::Eof
            || self.is_kw("end")
            || self.is_kw("else")
            || self.is_kw("elseif")
            || self.is_kw("until")
    }

    fn block(&mut self) -> Result<Vec<Stat>, String> {
        self.scopes.push(Vec::new());
        let mut out = Vec::new();
        while !self.block_ends() {
            if self.is_kw("return") {
                self.next();
                let values = if self.block_ends() || self.is_op(";") {
                    Vec::new()
                } else {
                    self.expr_list()?
                };
                if self.is_op(";") {
                    self.next();
                }
                out.push(Stat::Return(values));
                if !self.block_ends() {
                    return Err(format!("'<eof>' expected near {}", self.describe()));
                }
                break;
            }
            if let Some(s) = self.statement()? {
                out.push(s);
            }
        }
        self.scopes.pop();
        Ok(out)
    }

    fn statement(&mut self) -> Result<Option<Stat>, String> {
        if self.is_op(";") {
            self.next();
            return Ok(None);
        }
        if let Tok::Name(kw) = self.peek().clone() {
            match &*kw {
                "local" => return self.local_statement().map(Some),
                "if" => return self.if_statement().map(Some),
                "do" => {
                    self.next();
                    let body = self.block()?;
                    self.expect_kw("end")?;
                    return Ok(Some(Stat::Do(body)));
                }
                "while" | "for" | "repeat" | "break" | "goto" => {
                    return Err(format!(
                        "'{kw}' is not supported in DCCL conditions (no loops)"
                    ))
                }
                "function" => {
                    return Err("function definitions are not supported in DCCL conditions".into())
                }
                _ => {}
            }
        }
        if self.is_op("::") {
            return Err("labels are not supported in DCCL conditions".into());
        }
        let target = self.suffixed()?;
        if self.is_op("=") || self.is_op(",") {
            let Expr::Local(slot, _) = target else {
                return Err(match target {
                    Expr::Global(name) => format!(
                        "assigning to the global '{name}' is not supported in DCCL conditions \
                         (use 'local')"
                    ),
                    _ => "assigning to a table field is not supported in DCCL conditions".into(),
                });
            };
            if self.is_op(",") {
                return Err("multiple assignment is not supported in DCCL conditions".into());
            }
            self.next();
            let value = self.expr()?;
            return Ok(Some(Stat::Assign(slot, value)));
        }
        match target {
            Expr::Call(..) | Expr::Method(..) => Ok(Some(Stat::Call(target))),
            _ => Err(format!("syntax error near {}", self.describe())),
        }
    }

    fn local_statement(&mut self) -> Result<Stat, String> {
        self.next();
        if self.is_kw("function") {
            return Err("function definitions are not supported in DCCL conditions".into());
        }
        let mut names = vec![self.name()?];
        while self.is_op(",") {
            self.next();
            names.push(self.name()?);
        }
        let values = if self.is_op("=") {
            self.next();
            self.expr_list()?
        } else {
            Vec::new()
        };
        // The new locals are in scope after the statement.
        let mut slots = Vec::new();
        for n in names {
            let slot = self.slots;
            self.slots += 1;
            self.scopes.last_mut().expect("a block").push((n, slot));
            slots.push(slot);
        }
        Ok(Stat::Local(slots, values))
    }

    fn if_statement(&mut self) -> Result<Stat, String> {
        self.next();
        let mut arms = Vec::new();
        let cond = self.expr()?;
        self.expect_kw("then")?;
        arms.push((cond, self.block()?));
        let mut otherwise = None;
        loop {
            if self.is_kw("elseif") {
                self.next();
                let cond = self.expr()?;
                self.expect_kw("then")?;
                arms.push((cond, self.block()?));
            } else if self.is_kw("else") {
                self.next();
                otherwise = Some(self.block()?);
                self.expect_kw("end")?;
                break;
            } else {
                self.expect_kw("end")?;
                break;
            }
        }
        Ok(Stat::If(arms, otherwise))
    }

    fn expr_list(&mut self) -> Result<Vec<Expr>, String> {
        let mut out = vec![self.expr()?];
        while self.is_op(",") {
            self.next();
            out.push(self.expr()?);
        }
        Ok(out)
    }

    fn expr(&mut self) -> Result<Expr, String> {
        self.subexpr(0)
    }

    /// Lua's `subexpr`: operators binding tighter than `limit`.
    fn subexpr(&mut self, limit: u8) -> Result<Expr, String> {
        let unary = match self.peek() {
            Tok::Name(n) if &**n == "not" => Some(UnOp::Not),
            Tok::Op("-") => Some(UnOp::Neg),
            Tok::Op("#") => Some(UnOp::Len),
            Tok::Op("~") => Some(UnOp::BNot),
            _ => None,
        };
        let mut left = match unary {
            Some(op) => {
                self.next();
                let operand = self.subexpr(12)?;
                fold_unary(op, operand)
            }
            None => self.simple()?,
        };
        while let Some((op, lp, rp)) = self.binary_op() {
            if lp <= limit {
                break;
            }
            self.next();
            let right = self.subexpr(rp)?;
            left = match op {
                Bin::And => Expr::And(Box::new(left), Box::new(right)),
                Bin::Or => Expr::Or(Box::new(left), Box::new(right)),
                Bin::Op(op) => Expr::Bin(op, Box::new(left), Box::new(right)),
            };
        }
        Ok(left)
    }

    /// The binary operator ahead with its left and right priorities.
    fn binary_op(&self) -> Option<(Bin, u8, u8)> {
        use BinOp::*;
        let op = |o, l, r| Some((Bin::Op(o), l, r));
        match self.peek() {
            Tok::Op(o) => match *o {
                "+" => op(Add, 10, 10),
                "-" => op(Sub, 10, 10),
                "*" => op(Mul, 11, 11),
                "/" => op(Div, 11, 11),
                "//" => op(IDiv, 11, 11),
                "%" => op(Mod, 11, 11),
                "^" => op(Pow, 14, 13),
                ".." => op(Concat, 9, 8),
                "==" => op(Eq, 3, 3),
                "~=" => op(Ne, 3, 3),
                "<" => op(Lt, 3, 3),
                "<=" => op(Le, 3, 3),
                ">" => op(Gt, 3, 3),
                ">=" => op(Ge, 3, 3),
                "&" => op(BAnd, 6, 6),
                "|" => op(BOr, 4, 4),
                "~" => op(BXor, 5, 5),
                "<<" => op(Shl, 7, 7),
                ">>" => op(Shr, 7, 7),
                _ => None,
            },
            Tok::Name(n) if &**n == "and" => Some((Bin::And, 2, 2)),
            Tok::Name(n) if &**n == "or" => Some((Bin::Or, 1, 1)),
            _ => None,
        }
    }

    fn simple(&mut self) -> Result<Expr, String> {
        let e = match self.peek().clone() {
            Tok::Int(i) => Expr::Int(i),
            Tok::Num(f) => Expr::Num(f),
            Tok::Str(s) => Expr::Str(s),
            Tok::Name(n) if &*n == "nil" => Expr::Nil,
            Tok::Name(n) if &*n == "true" => Expr::Bool(true),
            Tok::Name(n) if &*n == "false" => Expr::Bool(false),
            Tok::Name(n) if &*n == "function" => {
                return Err("function definitions are not supported in DCCL conditions".into())
            }
            Tok::Op("...") => return Err("'...' is not supported in DCCL conditions".into()),
            Tok::Op("{") => {
                return Err("table constructors are not supported in DCCL conditions".into())
            }
            _ => return self.suffixed(),
        };
        self.next();
        Ok(e)
    }

    fn primary(&mut self) -> Result<Expr, String> {
        if self.is_op("(") {
            self.next();
            let e = self.expr()?;
            self.expect_op(")")?;
            return Ok(Expr::Paren(Box::new(e)));
        }
        let name = self.name()?;
        if let Some(slot) = self.local(&name) {
            return Ok(Expr::Local(slot, name));
        }
        if UNSUPPORTED.contains(&&*name) {
            return Err(format!("'{name}' is not supported in DCCL conditions"));
        }
        Ok(Expr::Global(name))
    }

    fn suffixed(&mut self) -> Result<Expr, String> {
        let mut e = self.primary()?;
        loop {
            if self.is_op(".") {
                self.next();
                let key = self.name()?;
                check_library_member(&e, &key)?;
                e = Expr::Index(Box::new(e), Box::new(Expr::Str(key.as_bytes().into())));
            } else if self.is_op("[") {
                self.next();
                let key = self.expr()?;
                self.expect_op("]")?;
                e = Expr::Index(Box::new(e), Box::new(key));
            } else if self.is_op(":") {
                self.next();
                let method = self.name()?;
                if !STRING.contains(&&*method) {
                    return Err(format!(
                        "the method '{method}' is not supported in DCCL conditions \
                         (supported: {})",
                        STRING.join(", ")
                    ));
                }
                let args = self.call_args()?;
                e = Expr::Method(Box::new(e), method, args);
            } else if self.is_op("(") || matches!(self.peek(), Tok::Str(_)) || self.is_op("{") {
                let args = self.call_args()?;
                e = Expr::Call(Box::new(e), args);
            } else {
                return Ok(e);
            }
        }
    }

    fn call_args(&mut self) -> Result<Vec<Expr>, String> {
        match self.peek().clone() {
            Tok::Str(s) => {
                self.next();
                Ok(vec![Expr::Str(s)])
            }
            Tok::Op("{") => Err("table constructors are not supported in DCCL conditions".into()),
            _ => {
                self.expect_op("(")?;
                if self.is_op(")") {
                    self.next();
                    return Ok(Vec::new());
                }
                let args = self.expr_list()?;
                self.expect_op(")")?;
                Ok(args)
            }
        }
    }
}

enum Bin {
    And,
    Or,
    Op(BinOp),
}

/// `-` of a numeral is the negative numeral (so that `-9223372036854775808`
/// stays an integer, as in Lua).
fn fold_unary(op: UnOp, operand: Expr) -> Expr {
    match (op, &operand) {
        (UnOp::Neg, Expr::Int(i)) => Expr::Int(i.wrapping_neg()),
        (UnOp::Neg, Expr::Num(f)) => Expr::Num(-f),
        _ => Expr::Un(op, Box::new(operand)),
    }
}

/// `math.X` and `string.X` must name a supported member.
fn check_library_member(table: &Expr, key: &str) -> Result<(), String> {
    let (lib, members) = match table {
        Expr::Global(g) if &**g == "math" => ("math", MATH),
        Expr::Global(g) if &**g == "string" => ("string", STRING),
        _ => return Ok(()),
    };
    if members.contains(&key) {
        Ok(())
    } else {
        Err(format!(
            "'{lib}.{key}' is not supported in DCCL conditions (supported: {})",
            members.join(", ")
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn libdccl_s_forms_parse() {
        for s in [
            "return this.state == 'STATE_1'",
            "this.state ~= 'STATE_2'",
            "this.c_center-100",
            "this_index*50+100",
            "this_index ~= 4",
            "print(this_index); return root.child[this_index].include_i == 'YES'",
            "root.child3.include_i == 'YES'",
            "local x = this.a if x > 2 then return true elseif x < 0 then return false else return nil end",
            "math.max(this.a, 2) // 3 % 2 ^ 2 .. 'x'",
            "#root.child >= 2 and not (this.b or false)",
            "('abc'):upper() == string.upper [[abc]]",
        ] {
            parse_script(s).unwrap_or_else(|e| panic!("{s}: {e}"));
        }
    }

    #[test]
    fn the_rest_is_refused_by_name() {
        for (s, why) in [
            ("for i=1,2 do end return true", "no loops"),
            ("x = 1 return x", "global 'x'"),
            ("os.time() > 0", "'os'"),
            ("math.sin(1)", "'math.sin'"),
            ("function f() end", "function"),
            ("#{1,2}", "table constructors"),
            ("this.a +", "unexpected symbol"),
            ("for i=1,2 do end", "no loops"),
            ("'abc", "unfinished string"),
            ("this.s:rep(2)", "'rep'"),
            ("return 1 2", "'<eof>' expected"),
        ] {
            let err = parse_script(s).expect_err(s);
            assert!(err.contains(why), "{s}: {err}");
        }
    }

    #[test]
    fn operators_bind_as_in_lua() {
        let Chunk { body, .. } = parse_script("-2^2").unwrap();
        let Stat::Return(v) = &body[0] else {
            panic!("{body:?}")
        };
        assert!(
            matches!(&v[0], Expr::Un(UnOp::Neg, e) if matches!(**e, Expr::Bin(BinOp::Pow, ..)))
        );
        let Chunk { body, .. } = parse_script("1 .. 2 .. 3").unwrap();
        let Stat::Return(v) = &body[0] else {
            panic!("{body:?}")
        };
        assert!(
            matches!(&v[0], Expr::Bin(BinOp::Concat, l, _) if matches!(**l, Expr::Int(1))),
            "{v:?}"
        );
    }
}
