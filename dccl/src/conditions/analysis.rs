//! What a condition script reads, found from its text before any message
//! is coded: the fields it names (each as its path of fields from the
//! root message), the names that are no field of their message, and
//! whether Lua 5.2 gives every result Lua 5.3 gives (Wireshark's Lua is
//! 5.2 in its 3.x and 4.x releases; libdccl's is 5.3).
//!
//! The values a script handles are followed by kind (nil, boolean, small
//! integer, other number, string, table) and, for messages and repeated
//! fields, by where they are in the message. Lua 5.2 has no integer
//! subtype: it writes the float `3.0` as `3` (`tostring`, `..` and the
//! string functions, which take numbers as text), has no `//`, no bitwise
//! operators and no `math.tointeger`, `math.type`, `math.maxinteger` or
//! `math.mininteger`, gives NaN where Lua 5.3 fails on an integer `% 0`,
//! converts the strings `math.max` and `math.min` compare, truncates a
//! fractional index to `string.sub`, and holds integers beyond 2^53 as
//! floats. A script doing none of that gives the same results in both.

use prost_reflect::{FieldDescriptor, Kind, MessageDescriptor};

use super::parser::{BinOp, Chunk, Expr, Stat, UnOp};

/// `this` of a script: its message type and its path of fields from the root.
#[derive(Debug, Clone)]
pub(crate) struct Place {
    pub desc: MessageDescriptor,
    pub path: Vec<FieldDescriptor>,
}

/// What a script reads.
#[derive(Debug, Default)]
pub(crate) struct Facts {
    /// The fields read, each as the longest path of fields from the root
    /// that the script follows, with how the script wrote it.
    pub reads: Vec<Read>,
    /// Names read that are no field of their message: why, one sentence each.
    pub unknown: Vec<String>,
    /// Why Lua 5.2 may give another result than Lua 5.3 (`None`: it gives
    /// the same).
    pub lua52: Option<String>,
}

/// A field a script reads.
#[derive(Debug, Clone)]
pub(crate) struct Read {
    /// The fields from the root (an element of a repeated field is its field).
    pub path: Vec<FieldDescriptor>,
    /// As the script wrote it (`root.n_wpt`, `this.a`).
    pub written: String,
}

const NIL: u8 = 1;
const BOOL: u8 = 2;
/// An integer whose text is the same in Lua 5.2 and 5.3 (under 10^14).
const SMALL: u8 = 4;
/// Another number: a float, or an integer that may be large.
const NUM: u8 = 8;
const STR: u8 = 16;
const TABLE: u8 = 32;
const FUNC: u8 = 64;
const ANY: u8 = NIL | BOOL | NUM | STR | TABLE | FUNC;

/// Where a table is.
#[derive(Debug, Clone)]
enum At {
    Msg {
        desc: MessageDescriptor,
        path: Vec<FieldDescriptor>,
        written: String,
    },
    List {
        field: FieldDescriptor,
        path: Vec<FieldDescriptor>,
        written: String,
    },
    Lib(&'static str),
    Func(String),
}

/// A value as far as the text tells.
#[derive(Debug, Clone)]
struct Abs {
    ty: u8,
    at: Option<At>,
    /// The value of a number constant.
    constant: Option<f64>,
}

impl Abs {
    fn of(ty: u8) -> Abs {
        Abs {
            ty,
            at: None,
            constant: None,
        }
    }

    fn join(&self, other: &Abs) -> Abs {
        Abs {
            ty: self.ty | other.ty,
            at: other.at.clone().or_else(|| self.at.clone()),
            constant: None,
        }
    }
}

/// What `chunk`, run with `this` and the root message `root`, reads.
pub(crate) fn facts(chunk: &Chunk, this: &Place, root: &MessageDescriptor) -> Facts {
    let mut walk = Walk {
        this,
        root,
        locals: vec![Abs::of(NIL); chunk.slots],
        facts: Facts::default(),
    };
    walk.block(&chunk.body);
    let mut facts = walk.facts;
    // Only the longest path of each chain (`root.a.b`, not also `root.a`).
    let all = facts.reads.clone();
    facts.reads.retain(|r| {
        !all.iter().any(|o| {
            o.path.len() > r.path.len()
                && o.written.starts_with(&r.written)
                && o.path.iter().zip(&r.path).all(|(a, b)| a == b)
        })
    });
    facts
}

struct Walk<'a> {
    this: &'a Place,
    root: &'a MessageDescriptor,
    locals: Vec<Abs>,
    facts: Facts,
}

impl Walk<'_> {
    fn differs(&mut self, why: impl FnOnce() -> String) {
        if self.facts.lua52.is_none() {
            self.facts.lua52 = Some(why());
        }
    }

    fn block(&mut self, body: &[Stat]) {
        for s in body {
            match s {
                Stat::Local(slots, values) => {
                    let vals = self.values(values);
                    for (i, slot) in slots.iter().enumerate() {
                        let v = match vals.get(i) {
                            Some(v) => v.clone(),
                            // More names than values: nil, or what a call
                            // returns beyond its first value.
                            None if matches!(
                                values.last(),
                                Some(Expr::Call(..) | Expr::Method(..))
                            ) =>
                            {
                                Abs::of(ANY)
                            }
                            None => Abs::of(NIL),
                        };
                        self.locals[*slot] = v;
                    }
                }
                Stat::Assign(slot, e) => {
                    let v = self.expr(e);
                    self.locals[*slot] = self.locals[*slot].join(&v);
                }
                Stat::Call(e) => {
                    self.expr(e);
                }
                Stat::If(arms, otherwise) => {
                    for (cond, b) in arms {
                        self.expr(cond);
                        self.block(b);
                    }
                    if let Some(b) = otherwise {
                        self.block(b);
                    }
                }
                Stat::Do(b) => self.block(b),
                Stat::Return(values) => {
                    self.values(values);
                }
            }
        }
    }

    fn values(&mut self, values: &[Expr]) -> Vec<Abs> {
        values.iter().map(|e| self.expr(e)).collect()
    }

    fn message(&self, desc: &MessageDescriptor, path: &[FieldDescriptor], written: &str) -> Abs {
        Abs {
            ty: TABLE,
            at: Some(At::Msg {
                desc: desc.clone(),
                path: path.to_vec(),
                written: written.to_string(),
            }),
            constant: None,
        }
    }

    fn expr(&mut self, e: &Expr) -> Abs {
        match e {
            Expr::Nil => Abs::of(NIL),
            Expr::Bool(_) => Abs::of(BOOL),
            Expr::Int(i) => {
                if i.unsigned_abs() > 1 << 53 {
                    self.differs(|| format!("the integer {i} (beyond 2^53)"));
                }
                Abs {
                    ty: if i.unsigned_abs() < 100_000_000_000_000 {
                        SMALL
                    } else {
                        NUM
                    },
                    at: None,
                    constant: Some(*i as f64),
                }
            }
            Expr::Num(f) => Abs {
                ty: NUM,
                at: None,
                constant: Some(*f),
            },
            Expr::Str(_) => Abs::of(STR),
            Expr::Global(name) => match &**name {
                "this" => self.message(&self.this.desc, &self.this.path, "this"),
                "root" => self.message(self.root, &[], "root"),
                "this_index" => Abs::of(SMALL),
                "math" => Abs {
                    ty: TABLE,
                    at: Some(At::Lib("math")),
                    constant: None,
                },
                "string" => Abs {
                    ty: TABLE,
                    at: Some(At::Lib("string")),
                    constant: None,
                },
                "print" | "tostring" | "tonumber" | "type" => Abs {
                    ty: FUNC,
                    at: Some(At::Func(name.to_string())),
                    constant: None,
                },
                _ => Abs::of(NIL),
            },
            Expr::Local(slot, _) => self.locals[*slot].clone(),
            Expr::Index(object, key) => {
                let o = self.expr(object);
                let k = self.expr(key);
                self.index(&o, key, &k)
            }
            Expr::Call(function, args) => {
                let f = self.expr(function);
                let a = self.values(args);
                match f.at {
                    Some(At::Func(name)) => self.call(&name, &a),
                    _ => Abs::of(ANY),
                }
            }
            Expr::Method(object, method, args) => {
                let mut a = vec![self.expr(object)];
                a.extend(self.values(args));
                self.call(&format!("string.{method}"), &a)
            }
            Expr::Bin(op, a, b) => {
                let a = self.expr(a);
                let b = self.expr(b);
                self.binary(*op, &a, &b)
            }
            Expr::Un(op, a) => {
                let a = self.expr(a);
                match op {
                    UnOp::Not => Abs::of(BOOL),
                    UnOp::Len => Abs::of(SMALL),
                    UnOp::Neg => Abs::of(NUM),
                    UnOp::BNot => {
                        self.differs(|| "the bitwise operator '~' (Lua 5.3)".into());
                        let _ = a;
                        Abs::of(NUM)
                    }
                }
            }
            Expr::And(a, b) | Expr::Or(a, b) => {
                let a = self.expr(a);
                let b = self.expr(b);
                Abs {
                    ty: a.ty | b.ty,
                    at: None,
                    constant: None,
                }
            }
            Expr::Paren(e) => self.expr(e),
        }
    }

    fn index(&mut self, object: &Abs, key: &Expr, k: &Abs) -> Abs {
        let name = match key {
            Expr::Str(s) => std::str::from_utf8(s).ok(),
            _ => None,
        };
        match (&object.at, name) {
            (
                Some(At::Msg {
                    desc,
                    path,
                    written,
                }),
                Some(name),
            ) => {
                let written = format!("{written}.{name}");
                if let Some(field) = desc.get_field_by_name(name) {
                    let mut path = path.clone();
                    path.push(field.clone());
                    self.facts.reads.push(Read {
                        path: path.clone(),
                        written: written.clone(),
                    });
                    return field_value(&field, path, written);
                }
                if let Some(oneof) = desc
                    .oneofs()
                    .find(|o| o.name() == name && !o.is_synthetic())
                {
                    // The name of the member set: each member is read.
                    for member in oneof.fields() {
                        let mut p = path.clone();
                        p.push(member);
                        self.facts.reads.push(Read {
                            path: p,
                            written: written.clone(),
                        });
                    }
                    return Abs::of(STR | NIL);
                }
                self.facts.unknown.push(format!(
                    "reads {written}: {} has no field {name} (the script sees nil)",
                    desc.full_name()
                ));
                Abs::of(NIL)
            }
            (Some(At::List { written, .. }), Some(name)) => {
                self.facts.unknown.push(format!(
                    "reads {written}.{name}: {written} is a repeated field, an array (the \
                     script sees nil; its elements are {written}[1], {written}[2]...)"
                ));
                Abs::of(NIL)
            }
            (
                Some(At::List {
                    field,
                    path,
                    written,
                }),
                None,
            ) if k.ty & (SMALL | NUM) != 0 => {
                let index = match key {
                    Expr::Int(i) => i.to_string(),
                    Expr::Global(g) => g.to_string(),
                    _ => "i".to_string(),
                };
                let written = format!("{written}[{index}]");
                let mut element = field_value_of_kind(field, path.clone(), written);
                element.ty |= NIL;
                element
            }
            (Some(At::Lib(lib)), Some(member)) => match (*lib, member) {
                ("math", "maxinteger" | "mininteger") => {
                    self.differs(|| format!("math.{member} (Lua 5.3)"));
                    Abs::of(NUM)
                }
                ("math", "huge" | "pi") => Abs::of(NUM),
                _ => Abs {
                    ty: FUNC,
                    at: Some(At::Func(format!("{lib}.{member}"))),
                    constant: None,
                },
            },
            // A string's methods (`s.len`), or nothing.
            _ if object.ty & STR != 0 => Abs::of(FUNC | NIL),
            _ => Abs::of(NIL),
        }
    }

    /// `what` of `v` as text: the same in Lua 5.2 for strings and small
    /// integers only.
    fn as_text(&mut self, v: &Abs, what: &str) {
        if v.ty & NUM != 0 {
            self.differs(|| {
                format!("{what} of a number that may be a float (Lua 5.2 writes 3.0 as 3)")
            });
        }
    }

    fn call(&mut self, name: &str, args: &[Abs]) -> Abs {
        let arg = |i: usize| args.get(i).cloned().unwrap_or_else(|| Abs::of(NIL));
        match name {
            "print" => Abs::of(NIL),
            "tostring" => {
                self.as_text(&arg(0), "tostring");
                Abs::of(STR)
            }
            "tonumber" => Abs::of(NUM | NIL),
            "type" => Abs::of(STR),
            "math.floor" | "math.ceil" | "math.abs" => {
                Abs::of(if arg(0).ty & NUM != 0 { NUM } else { SMALL })
            }
            "math.fmod" => {
                self.divisor(&arg(1), "math.fmod");
                Abs::of(NUM)
            }
            "math.max" | "math.min" => {
                if args.iter().any(|a| a.ty & STR != 0) {
                    self.differs(|| {
                        format!("{name} of strings (Lua 5.2 compares them as numbers)")
                    });
                }
                let numeric = args.iter().fold(0, |t, a| t | a.ty);
                Abs::of(if numeric & NUM != 0 { NUM } else { SMALL })
            }
            "math.tointeger" | "math.type" => {
                self.differs(|| format!("{name} (Lua 5.3)"));
                Abs::of(ANY)
            }
            "string.len" | "string.lower" | "string.upper" | "string.sub" => {
                self.as_text(&arg(0), name);
                if name == "string.sub" && args.iter().skip(1).any(|a| a.ty & NUM != 0) {
                    self.differs(|| {
                        "string.sub at an index that may be fractional (Lua 5.2 truncates it)"
                            .into()
                    });
                }
                Abs::of(if name == "string.len" { SMALL } else { STR })
            }
            _ => Abs::of(NUM),
        }
    }

    /// An integer divisor of 0 is an error in Lua 5.3, NaN in Lua 5.2: the
    /// same only for a constant other than 0.
    fn divisor(&mut self, b: &Abs, what: &str) {
        if !b.constant.is_some_and(|c| c != 0.0) {
            self.differs(|| {
                format!(
                    "{what} by a divisor that may be the integer 0 (an error in Lua 5.3, \
                     NaN in Lua 5.2)"
                )
            });
        }
    }

    fn binary(&mut self, op: BinOp, a: &Abs, b: &Abs) -> Abs {
        match op {
            BinOp::Eq | BinOp::Ne | BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge => Abs::of(BOOL),
            BinOp::Concat => {
                self.as_text(a, "'..'");
                self.as_text(b, "'..'");
                Abs::of(STR)
            }
            BinOp::Mod => {
                self.divisor(b, "'%'");
                Abs::of(NUM)
            }
            BinOp::IDiv => {
                self.differs(|| "the operator '//' (Lua 5.3)".into());
                Abs::of(NUM)
            }
            BinOp::BAnd | BinOp::BOr | BinOp::BXor | BinOp::Shl | BinOp::Shr => {
                self.differs(|| "bitwise operators (Lua 5.3)".into());
                Abs::of(NUM)
            }
            BinOp::Add | BinOp::Sub | BinOp::Mul | BinOp::Div | BinOp::Pow => Abs::of(NUM),
        }
    }
}

/// The value of `field` read from a message: a message, an array, or a
/// value of its kind (each nil when unset).
fn field_value(field: &FieldDescriptor, path: Vec<FieldDescriptor>, written: String) -> Abs {
    if field.is_list() {
        return Abs {
            ty: TABLE | NIL,
            at: Some(At::List {
                field: field.clone(),
                path,
                written,
            }),
            constant: None,
        };
    }
    let mut v = field_value_of_kind(field, path, written);
    v.ty |= NIL;
    v
}

/// A value of the kind of `field` (an element, for a repeated field).
fn field_value_of_kind(
    field: &FieldDescriptor,
    path: Vec<FieldDescriptor>,
    written: String,
) -> Abs {
    let ty = match field.kind() {
        Kind::Message(desc) => {
            return Abs {
                ty: TABLE,
                at: Some(At::Msg {
                    desc,
                    path,
                    written,
                }),
                constant: None,
            }
        }
        Kind::Bool => BOOL,
        Kind::String | Kind::Bytes | Kind::Enum(_) => STR,
        Kind::Float | Kind::Double => NUM,
        _ => {
            // An integer within its DCCL bounds, when they are small.
            let small = crate::options::field_options(field).is_ok_and(
                |o| matches!((o.min, o.max), (Some(a), Some(b)) if a.abs().max(b.abs()) < 1e14),
            );
            if small {
                SMALL
            } else {
                NUM
            }
        }
    };
    Abs::of(ty)
}

#[cfg(test)]
mod tests {
    use super::super::parser::parse_script;
    use super::*;

    fn pool() -> MessageDescriptor {
        let pool = crate::compile_sources(&[(
            "a.proto",
            r#"syntax = "proto2";
               import "dccl/option_extensions.proto";
               package a;
               message M {
                 option (dccl.msg) = { id: 1 max_bytes: 32 codec_version: 4 };
                 required int32 n = 1 [(dccl.field) = { min: 0 max: 10 }];
                 optional double d = 2 [(dccl.field) = { min: 0 max: 10 }];
                 optional string s = 3 [(dccl.field) = { max_length: 4 }];
                 message E { optional int32 k = 1 [(dccl.field) = { min: 0 max: 3 }]; }
                 repeated E e = 4 [(dccl.field).max_repeat = 2];
                 oneof o { int32 p = 5 [(dccl.field) = { min: 0 max: 3 }]; int32 q = 6 [(dccl.field) = { min: 0 max: 3 }]; }
               }"#,
        )])
        .unwrap();
        pool.get_message_by_name("a.M").unwrap()
    }

    fn of(script: &str) -> Facts {
        let root = pool();
        let chunk = parse_script(script).unwrap();
        facts(
            &chunk,
            &Place {
                desc: root.clone(),
                path: Vec::new(),
            },
            &root,
        )
    }

    fn read(f: &Facts) -> Vec<String> {
        f.reads
            .iter()
            .map(|r| {
                let names: Vec<&str> = r.path.iter().map(|f| f.name()).collect();
                format!("{} {}", r.written, names.join("."))
            })
            .collect()
    }

    #[test]
    fn the_fields_read_are_found_with_their_paths() {
        assert_eq!(read(&of("this.n > 2")), ["this.n n"]);
        assert_eq!(
            read(&of("root.e[this_index].k == 1 and root.e ~= nil")),
            ["root.e[this_index].k e.k"]
        );
        assert_eq!(read(&of("this.o == 'p'")), ["this.o p", "this.o q"]);
        assert_eq!(
            read(&of("local t = root.e[1] return t.k")),
            ["root.e[1].k e.k"]
        );
        let f = of("this.moode == 1 or root.e.k");
        assert_eq!(f.unknown.len(), 2, "{:?}", f.unknown);
        assert!(
            f.unknown[0].contains("a.M has no field moode"),
            "{:?}",
            f.unknown
        );
        assert!(
            f.unknown[1].contains("root.e is a repeated field"),
            "{:?}",
            f.unknown
        );
    }

    #[test]
    fn what_lua_5_2_gives_otherwise_is_found() {
        for same in [
            "this.n > 2",
            "this.n % 2 == 0",
            "(this.n .. '') == '1'",
            "tostring(this.n) == '1'",
            "string.len(this.s or '') >= 3",
            "this.s:upper() == 'AB'",
            "math.floor(this.d) + 1",
            "print(this_index); return root.e[this_index].k == 1",
            "this_index * 40 + 120",
            "math.max(this.d, 3)",
        ] {
            assert!(of(same).lua52.is_none(), "{same}: {:?}", of(same).lua52);
        }
        for (differs, why) in [
            (
                "tostring(this.d) == '1'",
                "tostring of a number that may be a float",
            ),
            ("(this.n / 1) .. ''", "'..' of a number"),
            ("this.n // 2", "'//'"),
            ("this.n & 1 == 1", "bitwise"),
            ("this.n % this.n == 0", "'%' by a divisor"),
            ("math.tointeger(this.d)", "math.tointeger"),
            ("math.maxinteger > 0", "math.maxinteger"),
            ("math.max('10', '9')", "math.max of strings"),
            ("string.sub(this.s, this.d)", "string.sub"),
            ("9007199254740993 > 0", "beyond 2^53"),
        ] {
            let f = of(differs);
            assert!(
                f.lua52.as_deref().is_some_and(|w| w.contains(why)),
                "{differs}: {:?}",
                f.lua52
            );
        }
    }
}
