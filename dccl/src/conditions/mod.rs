//! Dynamic conditions (`(dccl.field).dynamic_conditions`): `required_if`,
//! `omit_if`, `only_if`, `min` and `max`, scripts in the Lua language over
//! the message being coded, as libdccl 4.2 built with Lua evaluates them.
//!
//! The scripts run on an evaluator of this crate ([`parser`] and [`eval`]),
//! not on an embedded Lua: the crate builds without a C compiler. It takes
//! the part of Lua that conditions are written in — every expression form
//! (arithmetic, comparison, logic, `#`, `..`, bitwise operators, indexing,
//! calls), the statements `local`, assignment to a local, a call, `if`,
//! `do` and `return`, and the functions `print`, `tostring`, `tonumber`,
//! `type` and parts of `math` and `string` — with Lua 5.3's semantics
//! (integers and floats, string coercion, truthiness, Lua's error words).
//! Anything else (loops, function definitions, table constructors,
//! assignments to globals, other library functions) is refused when the
//! message is loaded, naming what is not supported.
//!
//! As in libdccl: a script without the word `return` is an expression
//! (`return ` is put before it); `this` is the message holding the field
//! (for the elements of a repeated field of messages, the element), `root`
//! the whole message, `this_index` Lua's index (from 1) of the element of
//! the last repeated field coded; while decoding, both see the message as
//! decoded so far.

mod analysis;
mod eval;
mod lexer;
mod library;
#[cfg(test)]
mod lua_differential;
mod number;
mod parser;
mod review;
mod trace;
mod view;

pub(crate) use eval::Env;
pub(crate) use review::review;
pub(crate) use trace::{first_difference, step, Step, Trace};
pub(crate) use view::{Frame, Node, Slot};

use std::cell::Cell;

use prost_reflect::{DynamicMessage, FieldDescriptor};
use protos::dccl::DcclFieldOptions;

use crate::error::CodecError;

/// What the conditions of a message being encoded see besides the message
/// holding the field: the root message, and the index (from 0) of the
/// element of the last repeated field coded (libdccl's `this_index` less 1:
/// it is not reset at the end of a repeated field).
#[derive(Debug, Clone, Copy)]
pub(crate) struct EncodeScope<'a> {
    pub root: &'a DynamicMessage,
    pub index: &'a Cell<i64>,
    /// Where each evaluation is recorded, when asked
    /// ([`crate::Codec::condition_outcomes`]).
    pub outcomes: Option<&'a std::cell::RefCell<Vec<ConditionOutcome>>>,
    /// Where the path taken is recorded, when asked ([`crate::Codec::round_trip`]).
    pub trace: Option<&'a Trace>,
}

impl EncodeScope<'_> {
    /// Records what a condition of `field` gave, when outcomes are collected.
    pub fn record(
        &self,
        field: &FieldDescriptor,
        condition: &'static str,
        result: impl FnOnce() -> String,
    ) {
        if let Some(log) = self.outcomes {
            log.borrow_mut().push(ConditionOutcome {
                message: field.parent_message().full_name().to_string(),
                field: field.name().to_string(),
                condition,
                result: result(),
            });
        }
    }
}

/// What one evaluation of a field's dynamic conditions gave while a message
/// was encoded (see [`crate::Codec::condition_outcomes`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConditionOutcome {
    /// Full name of the message type holding the field.
    pub message: String,
    /// The field's name.
    pub field: String,
    /// `"omit"` (`omit_if`, or `only_if` false), `"required"` (`required_if`,
    /// or `only_if` true) or `"bounds"` (`min`, `max`).
    pub condition: &'static str,
    /// `"true"` or `"false"`; for bounds, `[min, max]` in force and whether
    /// the value is inside them (`inside`, `outside`, `unset`).
    pub result: String,
}

/// A dynamic condition of a loaded type that may not do what its writer
/// meant, found when the type is loaded (see [`crate::Codec::load_warnings`]):
/// a condition that changes nothing for its field (`only_if` of a codec
/// version 2 field, `min` of a bool...), a script naming no field of its
/// message (it sees nil, as libdccl's Lua does), or a script reading a
/// field a receiver has not decoded yet when it evaluates the condition (a
/// later field, the field itself or a part of it: such a message may
/// encode, as libdccl encodes it, and then not decode as it was encoded).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DefinitionWarning {
    /// Full name of the message type holding the field.
    pub message: String,
    /// The field's name.
    pub field: String,
    /// `required_if`, `omit_if`, `only_if`, `min` or `max`.
    pub condition: &'static str,
    /// The script as written.
    pub script: String,
    /// What is wrong: `is ignored: ...` or `reads ...`.
    pub reason: String,
}

impl std::fmt::Display for DefinitionWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}.{}: dynamic_conditions.{} \"{}\" {}",
            self.message, self.field, self.condition, self.script, self.reason
        )
    }
}

/// Why Lua 5.2 may give another result than Lua 5.3 for the condition
/// `script` run with `this` a message of type `this` and `root` one of type
/// `root` (`Ok(None)`: it gives the same result for every message). Lua
/// 5.2 has no integer subtype (it writes the float `3.0` as `3`), no `//`,
/// no bitwise operators, no `math.tointeger`, `math.type`, `math.maxinteger`
/// or `math.mininteger`, and gives NaN for an integer `% 0`; a script using
/// none of these, nor `math.max`/`math.min` of strings, a fractional index
/// to `string.sub` or integers beyond 2^53, gives what it gives in Lua 5.3,
/// libdccl's. Errors when the script is not one DCCL conditions accept.
pub fn lua52_difference(
    script: &str,
    this: &prost_reflect::MessageDescriptor,
    root: &prost_reflect::MessageDescriptor,
) -> Result<Option<String>, CodecError> {
    let chunk = parser::parse_script(script)
        .map_err(|e| CodecError::new(format!("\"{script}\" cannot be used: {e}")))?;
    let this = analysis::Place {
        desc: this.clone(),
        path: Vec::new(),
    };
    Ok(analysis::facts(&chunk, &this, root).lua52)
}

/// What the conditions of a message being decoded see: the chain of the
/// messages above it (`parent`), where it goes in its parent (`slot`), its
/// depth below the root, and the index of the last repeated element decoded.
#[derive(Debug, Clone, Copy)]
pub(crate) struct DecodeScope<'a> {
    pub parent: Option<&'a Frame<'a>>,
    pub slot: Option<Slot<'a>>,
    pub depth: usize,
    pub index: &'a Cell<i64>,
    /// Where the path taken is recorded, when asked ([`crate::Codec::round_trip`]).
    pub trace: Option<&'a Trace>,
}

impl<'a> DecodeScope<'a> {
    /// The frame of `msg`, the message this scope is for.
    pub fn frame(&self, msg: &'a DynamicMessage) -> Frame<'a> {
        Frame {
            parent: self.parent,
            depth: self.depth,
            msg,
            slot: self.slot,
        }
    }

    /// The scope of a message one level below `frame`, going in `slot`.
    pub fn below(&self, frame: &'a Frame<'a>, slot: Slot<'a>) -> DecodeScope<'a> {
        DecodeScope {
            parent: Some(frame),
            slot: Some(slot),
            depth: frame.depth + 1,
            index: self.index,
            trace: self.trace,
        }
    }
}

/// The conditions' view of a frame: `this` the frame's message, `root` the
/// root of its chain.
pub(crate) fn frame_env<'a>(frame: &'a Frame<'a>, index: i64) -> Env<'a> {
    Env {
        this: Node::Chain(frame, frame.depth),
        root: Node::Chain(frame, 0),
        index: index + 1,
    }
}

/// One condition script: its text and its parsed form.
#[derive(Debug, Clone)]
pub(crate) struct Script {
    /// Which condition (`required_if`, `omit_if`, `only_if`, `min`, `max`).
    kind: &'static str,
    /// The script as written.
    source: String,
    chunk: parser::Chunk,
}

impl Script {
    fn parse(kind: &'static str, source: &str) -> Result<Script, CodecError> {
        let chunk = parser::parse_script(source).map_err(|e| {
            CodecError::new(format!(
                "dynamic_conditions.{kind} \"{source}\" cannot be used: {e}"
            ))
        })?;
        Ok(Script {
            kind,
            source: source.to_string(),
            chunk,
        })
    }

    fn failed(&self, why: &str) -> CodecError {
        CodecError::new(format!(
            "dynamic_conditions.{} \"{}\" failed: {why}",
            self.kind, self.source
        ))
    }

    /// Lua's truth of the first value the script returns (none: false).
    fn truth(&self, env: &Env<'_>) -> Result<bool, CodecError> {
        let values = eval::run(&self.chunk, env).map_err(|e| self.failed(&e))?;
        Ok(values.first().is_some_and(eval::Val::truthy))
    }

    /// The first value the script returns, as a number (numeric strings
    /// converted, as Lua converts them).
    fn number(&self, env: &Env<'_>) -> Result<f64, CodecError> {
        let values = eval::run(&self.chunk, env).map_err(|e| self.failed(&e))?;
        match values.first() {
            Some(v) => v
                .to_f64()
                .ok_or_else(|| self.failed(&format!("gave {}, not a number", v.lua_text()))),
            None => Err(self.failed("gave no value")),
        }
    }

    /// The script as written.
    pub fn source(&self) -> &str {
        &self.source
    }
}

/// The dynamic conditions of one field.
#[derive(Debug, Clone, Default)]
pub(crate) struct Conditions {
    required_if: Option<Script>,
    omit_if: Option<Script>,
    only_if: Option<Script>,
    min: Option<Script>,
    max: Option<Script>,
}

impl Conditions {
    /// The field's conditions, parsed; `None` when it has none.
    pub fn of(options: &DcclFieldOptions) -> Result<Option<Conditions>, CodecError> {
        let Some(dc) = &options.dynamic_conditions else {
            return Ok(None);
        };
        let parse =
            |kind, s: &Option<String>| s.as_deref().map(|s| Script::parse(kind, s)).transpose();
        Ok(Some(Conditions {
            required_if: parse("required_if", &dc.required_if)?,
            omit_if: parse("omit_if", &dc.omit_if)?,
            only_if: parse("only_if", &dc.only_if)?,
            min: parse("min", &dc.min)?,
            max: parse("max", &dc.max)?,
        }))
    }

    /// Whether a condition may leave the field out (`omit_if` or `only_if`).
    pub fn has_omit(&self) -> bool {
        self.omit_if.is_some() || self.only_if.is_some()
    }

    /// Whether a condition may make the field required (`required_if` or `only_if`).
    pub fn has_required(&self) -> bool {
        self.required_if.is_some() || self.only_if.is_some()
    }

    /// Whether the field's bounds are dynamic.
    pub fn has_bounds(&self) -> bool {
        self.min.is_some() || self.max.is_some()
    }

    /// Whether the field is left out: `omit_if`, else not `only_if`.
    pub fn omit(&self, env: &Env<'_>) -> Result<bool, CodecError> {
        match (&self.omit_if, &self.only_if) {
            (Some(s), _) => s.truth(env),
            (None, Some(s)) => Ok(!s.truth(env)?),
            _ => Ok(false),
        }
    }

    /// Whether the field is coded as required: `required_if`, else `only_if`.
    pub fn required(&self, env: &Env<'_>) -> Result<bool, CodecError> {
        match (&self.required_if, &self.only_if) {
            (Some(s), _) => s.truth(env),
            (None, Some(s)) => s.truth(env),
            _ => Ok(false),
        }
    }

    /// The bounds in force, as libdccl computes them: the dynamic ones kept
    /// within the static `[min, max]` (`min` at most the static maximum,
    /// `max` at least the static minimum).
    pub fn bounds(
        &self,
        env: &Env<'_>,
        static_min: f64,
        static_max: f64,
    ) -> Result<(f64, f64), CodecError> {
        let min = match &self.min {
            Some(s) => {
                let v = s.number(env)?;
                check_bound(s, v)?;
                static_max.min(v.max(static_min))
            }
            None => static_min,
        };
        let max = match &self.max {
            Some(s) => {
                let v = s.number(env)?;
                check_bound(s, v)?;
                static_min.max(v.min(static_max))
            }
            None => static_max,
        };
        if min > max {
            return Err(CodecError::new(format!(
                "dynamic_conditions give the bounds [{min}, {max}]: the minimum is over the maximum{}",
                self.scripts_text()
            )));
        }
        Ok((min, max))
    }

    /// The scripts given.
    pub(crate) fn scripts(&self) -> Vec<&Script> {
        [
            &self.required_if,
            &self.omit_if,
            &self.only_if,
            &self.min,
            &self.max,
        ]
        .into_iter()
        .flatten()
        .collect()
    }

    /// The scripts, for error messages and reports: `name "script"` each.
    pub fn describe(&self) -> Vec<(&'static str, &str)> {
        self.scripts()
            .into_iter()
            .map(|s| (s.kind, s.source()))
            .collect()
    }

    fn scripts_text(&self) -> String {
        let parts: Vec<String> = [&self.min, &self.max]
            .into_iter()
            .flatten()
            .map(|s| format!("{} \"{}\"", s.kind, s.source))
            .collect();
        if parts.is_empty() {
            String::new()
        } else {
            format!(" ({})", parts.join(", "))
        }
    }
}

fn check_bound(s: &Script, v: f64) -> Result<(), CodecError> {
    if v.is_nan() {
        return Err(s.failed("gave NaN"));
    }
    Ok(())
}
