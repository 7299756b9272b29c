//! Runs a parsed script as Lua 5.3 would: integer and float arithmetic
//! (integers wrap, `/` and `^` give floats, strings convert to numbers),
//! comparisons (integers and floats exactly, strings byte by byte),
//! truthiness (only `nil` and `false` are false), `and`/`or` short-circuits,
//! `#`, `..`, the bitwise operators, and the library functions of
//! the parser. A Lua error becomes an `Err` with Lua's words.

use std::sync::Arc;

use super::number::{
    float_le_int, float_lt_int, float_to_int, float_to_string, int_le_float, int_lt_float,
    string_to_number,
};
use super::parser::{BinOp, Chunk, Expr, Stat, UnOp};
use super::view::{List, Node};

/// A Lua value.
#[derive(Debug, Clone)]
pub(crate) enum Val<'a> {
    Nil,
    Bool(bool),
    Int(i64),
    Num(f64),
    Str(Arc<[u8]>),
    /// A message (a table).
    Msg(Node<'a>),
    /// A repeated field (an array table).
    List(List<'a>),
    /// `math` or `string`.
    Lib(&'static str),
    /// A library function, by its full name (`tostring`, `math.floor`...).
    Func(&'static str),
}

impl Val<'_> {
    /// Lua's `type` of the value.
    pub fn type_name(&self) -> &'static str {
        match self {
            Val::Nil => "nil",
            Val::Bool(_) => "boolean",
            Val::Int(_) | Val::Num(_) => "number",
            Val::Str(_) => "string",
            Val::Msg(_) | Val::List(_) | Val::Lib(_) => "table",
            Val::Func(_) => "function",
        }
    }

    /// Lua's truth: all but `nil` and `false`.
    pub fn truthy(&self) -> bool {
        !matches!(self, Val::Nil | Val::Bool(false))
    }

    /// As a number (strings converted), for arithmetic.
    fn to_number(&self) -> Option<Val<'static>> {
        match self {
            Val::Int(i) => Some(Val::Int(*i)),
            Val::Num(f) => Some(Val::Num(*f)),
            Val::Str(s) => string_to_number(s),
            _ => None,
        }
    }

    /// As a double (Lua's `lua_tonumber`): numbers and numeric strings.
    pub fn to_f64(&self) -> Option<f64> {
        match self.to_number()? {
            Val::Int(i) => Some(i as f64),
            Val::Num(f) => Some(f),
            _ => None,
        }
    }

    /// As an integer with the same value (Lua's integer conversion).
    pub fn to_int(&self) -> Option<i64> {
        match self.to_number()? {
            Val::Int(i) => Some(i),
            Val::Num(f) => float_to_int(f),
            _ => None,
        }
    }

    /// The value as a Lua programmer writes or reads it, for error
    /// messages: `nil`, `true (a boolean)`, `3`, `2.5`, `"five" (a
    /// string)`, `a table`, `a function`.
    pub fn lua_text(&self) -> String {
        match self {
            Val::Nil => "nil".to_string(),
            Val::Bool(b) => format!("{b} (a boolean)"),
            Val::Int(i) => i.to_string(),
            Val::Num(f) => float_to_string(*f),
            Val::Str(s) => {
                let mut out = String::from("\"");
                for &b in s.iter() {
                    match b {
                        b'"' => out.push_str("\\\""),
                        b'\\' => out.push_str("\\\\"),
                        b'\n' => out.push_str("\\n"),
                        0x20..=0x7e => out.push(char::from(b)),
                        _ => out.push_str(&format!("\\{b}")),
                    }
                }
                out.push_str("\" (a string)");
                out
            }
            Val::Msg(_) | Val::List(_) | Val::Lib(_) => "a table".to_string(),
            Val::Func(_) => "a function".to_string(),
        }
    }

    /// `tostring` of a number or string.
    fn to_text(&self) -> Option<Vec<u8>> {
        match self {
            Val::Int(i) => Some(i.to_string().into_bytes()),
            Val::Num(f) => Some(float_to_string(*f).into_bytes()),
            Val::Str(s) => Some(s.to_vec()),
            _ => None,
        }
    }
}

/// What `this`, `root` and `this_index` are for one evaluation.
#[derive(Debug, Clone)]
pub(crate) struct Env<'a> {
    pub this: Node<'a>,
    pub root: Node<'a>,
    /// Lua's index (from 1) of the current element of a repeated field.
    pub index: i64,
}

/// How a value was reached, for error messages (`global 'x'`, `field 'y'`).
fn describe(e: &Expr) -> String {
    match e {
        Expr::Global(n) => format!(" (global '{n}')"),
        Expr::Local(_, n) => format!(" (local '{n}')"),
        Expr::Index(_, k) => match &**k {
            Expr::Str(s) => format!(" (field '{}')", String::from_utf8_lossy(s)),
            _ => String::new(),
        },
        Expr::Method(_, m, _) => format!(" (method '{m}')"),
        _ => String::new(),
    }
}

/// The values a script returns (empty when it returns none).
pub(crate) fn run<'a>(chunk: &Chunk, env: &Env<'a>) -> Result<Vec<Val<'a>>, String> {
    let mut m = Machine {
        env,
        locals: vec![Val::Nil; chunk.slots],
    };
    Ok(m.block(&chunk.body)?.unwrap_or_default())
}

struct Machine<'e, 'a> {
    env: &'e Env<'a>,
    locals: Vec<Val<'a>>,
}

impl<'a> Machine<'_, 'a> {
    /// Runs statements; `Some` when a `return` ran.
    fn block(&mut self, body: &[Stat]) -> Result<Option<Vec<Val<'a>>>, String> {
        for s in body {
            match s {
                Stat::Local(slots, values) => {
                    let mut vals = Vec::new();
                    for (i, e) in values.iter().enumerate() {
                        if i + 1 == values.len() {
                            vals.extend(self.multi(e)?);
                        } else {
                            vals.push(self.eval(e)?);
                        }
                    }
                    for (i, slot) in slots.iter().enumerate() {
                        self.locals[*slot] = vals.get(i).cloned().unwrap_or(Val::Nil);
                    }
                }
                Stat::Assign(slot, e) => self.locals[*slot] = self.eval(e)?,
                Stat::Call(e) => {
                    self.multi(e)?;
                }
                Stat::If(arms, otherwise) => {
                    let mut taken = None;
                    for (cond, body) in arms {
                        if self.eval(cond)?.truthy() {
                            taken = Some(body);
                            break;
                        }
                    }
                    if let Some(body) = taken.or(otherwise.as_ref()) {
                        if let Some(r) = self.block(body)? {
                            return Ok(Some(r));
                        }
                    }
                }
                Stat::Do(body) => {
                    if let Some(r) = self.block(body)? {
                        return Ok(Some(r));
                    }
                }
                Stat::Return(values) => {
                    let mut out = Vec::new();
                    for (i, e) in values.iter().enumerate() {
                        if i + 1 == values.len() {
                            out.extend(self.multi(e)?);
                        } else {
                            out.push(self.eval(e)?);
                        }
                    }
                    return Ok(Some(out));
                }
            }
        }
        Ok(None)
    }

    /// An expression's values (a call may give none).
    fn multi(&mut self, e: &Expr) -> Result<Vec<Val<'a>>, String> {
        match e {
            Expr::Call(f, args) => {
                let func = self.eval(f)?;
                let args = self.args(args)?;
                Ok(self.call(&func, &args, f)?.into_iter().collect())
            }
            Expr::Method(obj, name, args) => {
                let obj_val = self.eval(obj)?;
                let func = self.index(&obj_val, &Val::Str(name.as_bytes().into()), obj)?;
                let mut all = vec![obj_val];
                all.extend(self.args(args)?);
                Ok(self.call(&func, &all, e)?.into_iter().collect())
            }
            _ => Ok(vec![self.eval(e)?]),
        }
    }

    fn args(&mut self, args: &[Expr]) -> Result<Vec<Val<'a>>, String> {
        let mut out = Vec::with_capacity(args.len());
        for (i, a) in args.iter().enumerate() {
            if i + 1 == args.len() {
                out.extend(self.multi(a)?);
            } else {
                out.push(self.eval(a)?);
            }
        }
        Ok(out)
    }

    fn eval(&mut self, e: &Expr) -> Result<Val<'a>, String> {
        Ok(match e {
            Expr::Nil => Val::Nil,
            Expr::Bool(b) => Val::Bool(*b),
            Expr::Int(i) => Val::Int(*i),
            Expr::Num(f) => Val::Num(*f),
            Expr::Str(s) => Val::Str(s.clone()),
            Expr::Local(slot, _) => self.locals[*slot].clone(),
            Expr::Global(name) => match &**name {
                "this" => Val::Msg(self.env.this.clone()),
                "root" => Val::Msg(self.env.root.clone()),
                "this_index" => Val::Int(self.env.index),
                "math" => Val::Lib("math"),
                "string" => Val::Lib("string"),
                "print" => Val::Func("print"),
                "tostring" => Val::Func("tostring"),
                "tonumber" => Val::Func("tonumber"),
                "type" => Val::Func("type"),
                _ => Val::Nil,
            },
            Expr::Index(t, k) => {
                let table = self.eval(t)?;
                let key = self.eval(k)?;
                self.index(&table, &key, t)?
            }
            Expr::Call(..) | Expr::Method(..) => {
                self.multi(e)?.into_iter().next().unwrap_or(Val::Nil)
            }
            Expr::Paren(inner) => self.eval(inner)?,
            Expr::And(l, r) => {
                let l = self.eval(l)?;
                if l.truthy() {
                    self.eval(r)?
                } else {
                    l
                }
            }
            Expr::Or(l, r) => {
                let l = self.eval(l)?;
                if l.truthy() {
                    l
                } else {
                    self.eval(r)?
                }
            }
            Expr::Un(op, x) => {
                let v = self.eval(x)?;
                unary(*op, &v).map_err(|m| format!("{m}{}", describe(x)))?
            }
            Expr::Bin(op, l, r) => {
                let a = self.eval(l)?;
                let b = self.eval(r)?;
                binary(*op, &a, &b).map_err(|m| {
                    // Lua names the operand at fault.
                    let culprit = if a.to_number().is_some()
                        || matches!(op, BinOp::Concat) && a.to_text().is_some()
                    {
                        r
                    } else {
                        l
                    };
                    format!("{m}{}", describe(culprit))
                })?
            }
        })
    }

    fn index(&self, t: &Val<'a>, k: &Val<'a>, from: &Expr) -> Result<Val<'a>, String> {
        Ok(match (t, k) {
            (Val::Msg(node), Val::Str(name)) => node.get(name),
            (Val::Msg(_), _) => Val::Nil,
            (Val::List(list), key) => match key {
                Val::Int(i) => list_get(list, *i),
                Val::Num(f) => float_to_int(*f).map_or(Val::Nil, |i| list_get(list, i)),
                _ => Val::Nil,
            },
            (Val::Lib(lib), Val::Str(name)) => library_member(lib, name),
            (Val::Lib(_), _) => Val::Nil,
            (Val::Str(_), Val::Str(name)) => library_member("string", name),
            (Val::Str(_), _) => Val::Nil,
            _ => {
                return Err(format!(
                    "attempt to index a {} value{}",
                    t.type_name(),
                    describe(from)
                ))
            }
        })
    }

    fn call(&self, f: &Val<'a>, args: &[Val<'a>], from: &Expr) -> Result<Option<Val<'a>>, String> {
        let Val::Func(name) = f else {
            return Err(format!(
                "attempt to call a {} value{}",
                f.type_name(),
                describe(from)
            ));
        };
        super::library::call(name, args)
    }
}

fn list_get<'a>(list: &List<'a>, i: i64) -> Val<'a> {
    if i >= 1 && (i as u64) <= list.len() as u64 {
        list.get((i - 1) as usize)
    } else {
        Val::Nil
    }
}

fn library_member(lib: &str, name: &[u8]) -> Val<'static> {
    use super::parser::{MATH, STRING};
    let Ok(name) = std::str::from_utf8(name) else {
        return Val::Nil;
    };
    match (lib, name) {
        ("math", "huge") => Val::Num(f64::INFINITY),
        ("math", "pi") => Val::Num(std::f64::consts::PI),
        ("math", "maxinteger") => Val::Int(i64::MAX),
        ("math", "mininteger") => Val::Int(i64::MIN),
        ("math", n) => MATH
            .iter()
            .find(|m| **m == n)
            .map_or(Val::Nil, |m| Val::Func(super::library::math_name(m))),
        ("string", n) => STRING
            .iter()
            .find(|m| **m == n)
            .map_or(Val::Nil, |m| Val::Func(super::library::string_name(m))),
        _ => Val::Nil,
    }
}

fn unary<'a>(op: UnOp, v: &Val<'a>) -> Result<Val<'a>, String> {
    Ok(match op {
        UnOp::Not => Val::Bool(!v.truthy()),
        UnOp::Neg => match v.to_number() {
            Some(Val::Int(i)) if !matches!(v, Val::Str(_)) => Val::Int(i.wrapping_neg()),
            Some(Val::Int(i)) => Val::Num(-(i as f64)),
            Some(Val::Num(f)) => Val::Num(-f),
            _ => {
                return Err(format!(
                    "attempt to perform arithmetic on a {} value",
                    v.type_name()
                ))
            }
        },
        UnOp::Len => match v {
            Val::Str(s) => Val::Int(s.len() as i64),
            Val::List(l) => Val::Int(l.len() as i64),
            Val::Msg(_) | Val::Lib(_) => Val::Int(0),
            _ => {
                return Err(format!(
                    "attempt to get length of a {} value",
                    v.type_name()
                ))
            }
        },
        UnOp::BNot => Val::Int(!bit_operand(v)?),
    })
}

fn bit_operand(v: &Val<'_>) -> Result<i64, String> {
    match v.to_number() {
        None => Err(format!(
            "attempt to perform bitwise operation on a {} value",
            v.type_name()
        )),
        Some(_) => v
            .to_int()
            .ok_or_else(|| "number has no integer representation".to_string()),
    }
}

/// Lua's comparison `a < b` (`le`: `a <= b`).
pub(crate) fn less<'a>(a: &Val<'a>, b: &Val<'a>, le: bool) -> Result<bool, String> {
    Ok(match (a, b) {
        (Val::Int(x), Val::Int(y)) => {
            if le {
                x <= y
            } else {
                x < y
            }
        }
        (Val::Num(x), Val::Num(y)) => {
            if le {
                x <= y
            } else {
                x < y
            }
        }
        (Val::Int(x), Val::Num(y)) => {
            if le {
                int_le_float(*x, *y)
            } else {
                int_lt_float(*x, *y)
            }
        }
        (Val::Num(x), Val::Int(y)) => {
            if le {
                float_le_int(*x, *y)
            } else {
                float_lt_int(*x, *y)
            }
        }
        (Val::Str(x), Val::Str(y)) => {
            if le {
                x <= y
            } else {
                x < y
            }
        }
        _ => {
            let (ta, tb) = (a.type_name(), b.type_name());
            return Err(if ta == tb {
                format!("attempt to compare two {ta} values")
            } else {
                format!("attempt to compare {ta} with {tb}")
            });
        }
    })
}

/// Lua's raw equality.
fn equal(a: &Val<'_>, b: &Val<'_>) -> bool {
    match (a, b) {
        (Val::Nil, Val::Nil) => true,
        (Val::Bool(x), Val::Bool(y)) => x == y,
        (Val::Int(x), Val::Int(y)) => x == y,
        (Val::Num(x), Val::Num(y)) => x == y,
        (Val::Int(i), Val::Num(f)) | (Val::Num(f), Val::Int(i)) => float_to_int(*f) == Some(*i),
        (Val::Str(x), Val::Str(y)) => x == y,
        (Val::Msg(x), Val::Msg(y)) => x.identity() != 0 && x.identity() == y.identity(),
        (Val::Lib(x), Val::Lib(y)) | (Val::Func(x), Val::Func(y)) => x == y,
        _ => false,
    }
}

fn arith_error(a: &Val<'_>, b: &Val<'_>) -> String {
    let bad = if a.to_number().is_none() { a } else { b };
    if let Val::Str(_) = bad {
        "attempt to perform arithmetic on a string value".to_string()
    } else {
        format!(
            "attempt to perform arithmetic on a {} value",
            bad.type_name()
        )
    }
}

fn binary<'a>(op: BinOp, a: &Val<'a>, b: &Val<'a>) -> Result<Val<'a>, String> {
    use BinOp::*;
    Ok(match op {
        Eq => Val::Bool(equal(a, b)),
        Ne => Val::Bool(!equal(a, b)),
        Lt => Val::Bool(less(a, b, false)?),
        Le => Val::Bool(less(a, b, true)?),
        Gt => Val::Bool(less(b, a, false)?),
        Ge => Val::Bool(less(b, a, true)?),
        Concat => match (a.to_text(), b.to_text()) {
            (Some(mut x), Some(y)) => {
                x.extend(y);
                Val::Str(x.into())
            }
            _ => {
                let bad = if a.to_text().is_none() { a } else { b };
                return Err(format!(
                    "attempt to concatenate a {} value",
                    bad.type_name()
                ));
            }
        },
        BAnd | BOr | BXor | Shl | Shr => {
            let (x, y) = (bit_operand(a)?, bit_operand(b)?);
            Val::Int(match op {
                BAnd => x & y,
                BOr => x | y,
                BXor => x ^ y,
                Shl => shift_left(x, y),
                _ => shift_left(x, y.wrapping_neg()),
            })
        }
        Add | Sub | Mul | Div | IDiv | Mod | Pow => {
            let (Some(x), Some(y)) = (a.to_number(), b.to_number()) else {
                return Err(arith_error(a, b));
            };
            // Lua 5.3 converts a string operand to a float.
            if matches!(a, Val::Str(_)) || matches!(b, Val::Str(_)) {
                arith(op, &Val::Num(as_float(&x)), &Val::Num(as_float(&y)))?
            } else {
                arith(op, &x, &y)?
            }
        }
    })
}

fn as_float(v: &Val<'_>) -> f64 {
    match v {
        Val::Int(i) => *i as f64,
        Val::Num(f) => *f,
        _ => f64::NAN,
    }
}

/// Lua's logical shift (negative counts shift the other way).
fn shift_left(x: i64, n: i64) -> i64 {
    if n <= -64 || n >= 64 {
        0
    } else if n >= 0 {
        ((x as u64) << n) as i64
    } else {
        ((x as u64) >> (-n)) as i64
    }
}

fn arith<'a>(op: BinOp, x: &Val<'static>, y: &Val<'static>) -> Result<Val<'a>, String> {
    use BinOp::*;
    if let (Val::Int(a), Val::Int(b)) = (x, y) {
        let (a, b) = (*a, *b);
        match op {
            Add => return Ok(Val::Int(a.wrapping_add(b))),
            Sub => return Ok(Val::Int(a.wrapping_sub(b))),
            Mul => return Ok(Val::Int(a.wrapping_mul(b))),
            IDiv => {
                if b == 0 {
                    return Err("attempt to perform 'n//0'".to_string());
                }
                if b == -1 {
                    return Ok(Val::Int(a.wrapping_neg()));
                }
                let q = a / b;
                return Ok(Val::Int(if (a % b != 0) && ((a < 0) != (b < 0)) {
                    q - 1
                } else {
                    q
                }));
            }
            Mod => {
                if b == 0 {
                    return Err("attempt to perform 'n%0'".to_string());
                }
                if b == -1 {
                    return Ok(Val::Int(0));
                }
                let r = a % b;
                return Ok(Val::Int(if r != 0 && ((r ^ b) < 0) { r + b } else { r }));
            }
            _ => {}
        }
    }
    let f = |v: &Val<'_>| match v {
        Val::Int(i) => *i as f64,
        Val::Num(n) => *n,
        _ => f64::NAN,
    };
    let (a, b) = (f(x), f(y));
    Ok(Val::Num(match op {
        Add => a + b,
        Sub => a - b,
        Mul => a * b,
        Div => a / b,
        Pow => a.powf(b),
        IDiv => (a / b).floor(),
        _ => {
            let m = a % b;
            if m * b < 0.0 {
                m + b
            } else {
                m
            }
        }
    }))
}
