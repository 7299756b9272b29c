//! The Lua library functions condition scripts may call: `print` (which
//! writes nothing here), `tostring`, `tonumber`, `type`, and the members of
//! `math` and `string` listed in [`super::parser`], each as Lua 5.3 defines
//! it.

use super::eval::Val;
use super::number::{float_to_int, float_to_string, string_to_number};

/// The full name of a `math` member.
pub(crate) fn math_name(m: &str) -> &'static str {
    match m {
        "abs" => "math.abs",
        "ceil" => "math.ceil",
        "floor" => "math.floor",
        "fmod" => "math.fmod",
        "max" => "math.max",
        "min" => "math.min",
        "sqrt" => "math.sqrt",
        "tointeger" => "math.tointeger",
        _ => "math.type",
    }
}

/// The full name of a `string` member.
pub(crate) fn string_name(m: &str) -> &'static str {
    match m {
        "len" => "string.len",
        "lower" => "string.lower",
        "sub" => "string.sub",
        _ => "string.upper",
    }
}

fn arg_error(n: usize, name: &str, expected: &str, got: Option<&Val<'_>>) -> String {
    let short = name.rsplit('.').next().unwrap_or(name);
    let got = match got {
        None => "no value".to_string(),
        Some(v) => type_of(v).to_string(),
    };
    format!("bad argument #{n} to '{short}' ({expected} expected, got {got})")
}

fn type_of(v: &Val<'_>) -> &'static str {
    v.type_name()
}

/// Argument `n` (from 1) as a number.
fn number<'a>(args: &[Val<'a>], n: usize, name: &str) -> Result<Val<'a>, String> {
    let v = args.get(n - 1);
    match v {
        Some(Val::Int(i)) => Ok(Val::Int(*i)),
        Some(Val::Num(f)) => Ok(Val::Num(*f)),
        // A string argument is read as a float (Lua's `lua_tonumber`).
        Some(Val::Str(s)) => string_to_number(s)
            .map(|v| match v {
                Val::Int(i) => Val::Num(i as f64),
                Val::Num(f) => Val::Num(f),
                _ => Val::Nil,
            })
            .ok_or_else(|| arg_error(n, name, "number", v)),
        _ => Err(arg_error(n, name, "number", v)),
    }
}

/// Argument `n` as an integer (floats with an integer value accepted).
fn integer(args: &[Val<'_>], n: usize, name: &str) -> Result<i64, String> {
    match number(args, n, name)? {
        Val::Int(i) => Ok(i),
        Val::Num(f) => float_to_int(f).ok_or_else(|| {
            let short = name.rsplit('.').next().unwrap_or(name);
            format!("bad argument #{n} to '{short}' (number has no integer representation)")
        }),
        _ => Err(arg_error(n, name, "number", args.get(n - 1))),
    }
}

/// Argument `n` as a string (numbers converted).
fn string(args: &[Val<'_>], n: usize, name: &str) -> Result<Vec<u8>, String> {
    match args.get(n - 1) {
        Some(Val::Str(s)) => Ok(s.to_vec()),
        Some(Val::Int(i)) => Ok(i.to_string().into_bytes()),
        Some(Val::Num(f)) => Ok(float_to_string(*f).into_bytes()),
        v => Err(arg_error(n, name, "string", v)),
    }
}

fn as_f64(v: &Val<'_>) -> f64 {
    match v {
        Val::Int(i) => *i as f64,
        Val::Num(f) => *f,
        _ => f64::NAN,
    }
}

/// A float result that fits an integer becomes one (`math.floor`, `math.ceil`).
fn int_if_fits<'a>(f: f64) -> Val<'a> {
    float_to_int(f).map_or(Val::Num(f), Val::Int)
}

/// Calls the library function `name`; `None` when it returns no value.
pub(crate) fn call<'a>(name: &str, args: &[Val<'a>]) -> Result<Option<Val<'a>>, String> {
    let one = |v: Val<'a>| Ok(Some(v));
    match name {
        "print" => Ok(None),
        "type" => match args.first() {
            Some(v) => one(Val::Str(type_of(v).as_bytes().into())),
            None => Err("bad argument #1 to 'type' (value expected)".to_string()),
        },
        "tostring" => match args.first() {
            None => Err("bad argument #1 to 'tostring' (value expected)".to_string()),
            Some(Val::Nil) => one(Val::Str(b"nil"[..].into())),
            Some(Val::Bool(b)) => one(Val::Str(b.to_string().as_bytes().into())),
            Some(v @ (Val::Int(_) | Val::Num(_) | Val::Str(_))) => {
                one(Val::Str(string(std::slice::from_ref(v), 1, name)?.into()))
            }
            Some(_) => Err(
                "tostring of a table or function is not supported in DCCL conditions".to_string(),
            ),
        },
        "tonumber" => {
            if args.len() > 1 {
                return Err("tonumber with a base is not supported in DCCL conditions".to_string());
            }
            match args.first() {
                None => Err("bad argument #1 to 'tonumber' (value expected)".to_string()),
                Some(Val::Int(i)) => one(Val::Int(*i)),
                Some(Val::Num(f)) => one(Val::Num(*f)),
                Some(Val::Str(s)) => one(match string_to_number(s) {
                    Some(Val::Int(i)) => Val::Int(i),
                    Some(Val::Num(f)) => Val::Num(f),
                    _ => Val::Nil,
                }),
                Some(_) => one(Val::Nil),
            }
        }
        "math.abs" => match number(args, 1, name)? {
            Val::Int(i) => one(Val::Int(i.wrapping_abs())),
            v => one(Val::Num(as_f64(&v).abs())),
        },
        "math.floor" => match number(args, 1, name)? {
            Val::Int(i) => one(Val::Int(i)),
            v => one(int_if_fits(as_f64(&v).floor())),
        },
        "math.ceil" => match number(args, 1, name)? {
            Val::Int(i) => one(Val::Int(i)),
            v => one(int_if_fits(as_f64(&v).ceil())),
        },
        "math.sqrt" => one(Val::Num(as_f64(&number(args, 1, name)?).sqrt())),
        "math.tointeger" => match args.first() {
            None => Err("bad argument #1 to 'tointeger' (value expected)".to_string()),
            Some(v) => one(v.to_int().map_or(Val::Nil, Val::Int)),
        },
        "math.type" => match args.first() {
            None => Err("bad argument #1 to 'type' (value expected)".to_string()),
            Some(Val::Int(_)) => one(Val::Str(b"integer"[..].into())),
            Some(Val::Num(_)) => one(Val::Str(b"float"[..].into())),
            Some(_) => one(Val::Nil),
        },
        "math.fmod" => match (number(args, 1, name)?, number(args, 2, name)?) {
            (Val::Int(a), Val::Int(b)) => {
                if b == 0 {
                    Err("bad argument #2 to 'fmod' (zero)".to_string())
                } else if b == -1 {
                    one(Val::Int(0))
                } else {
                    one(Val::Int(a % b))
                }
            }
            (a, b) => one(Val::Num(as_f64(&a) % as_f64(&b))),
        },
        "math.max" | "math.min" => {
            // As Lua 5.3: the arguments are compared as they are (strings
            // as strings, a string with a number an error) and the one
            // chosen returned.
            let Some(mut best) = args.first() else {
                let short = &name[5..];
                return Err(format!("bad argument #1 to '{short}' (value expected)"));
            };
            for v in &args[1..] {
                let better = if name == "math.max" {
                    super::eval::less(best, v, false)?
                } else {
                    super::eval::less(v, best, false)?
                };
                if better {
                    best = v;
                }
            }
            one(best.clone())
        }
        "string.len" => one(Val::Int(string(args, 1, name)?.len() as i64)),
        "string.upper" => one(Val::Str(string(args, 1, name)?.to_ascii_uppercase().into())),
        "string.lower" => one(Val::Str(string(args, 1, name)?.to_ascii_lowercase().into())),
        "string.sub" => {
            let s = string(args, 1, name)?;
            let len = s.len() as i64;
            let i = if args.len() >= 2 {
                integer(args, 2, name)?
            } else {
                1
            };
            let j = if args.len() >= 3 {
                integer(args, 3, name)?
            } else {
                -1
            };
            let start = if i < 0 {
                (len + i + 1).max(1)
            } else {
                i.max(1)
            };
            let end = if j < 0 { len + j + 1 } else { j.min(len) };
            one(Val::Str(if start > end {
                Vec::new().into()
            } else {
                s[(start - 1) as usize..end as usize].to_vec().into()
            }))
        }
        other => Err(format!("'{other}' is not supported in DCCL conditions")),
    }
}
