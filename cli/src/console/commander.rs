//! The commander's codec: the DCCL types of the `-f` files, their forms
//! ([`schema`](super::schema)), and the check of a draft before it is
//! sent — what the codec would change (values out of range, truncated,
//! rounded to their precision, times moved to another day), its size, and
//! the message as its receiver would decode it.

use std::collections::HashMap;
use std::io::Write;

use dccl::Codec;
use prost_reflect::{DynamicMessage, MessageDescriptor};
use serde_json::{json, Value};

use super::schema::message_form;
use super::state::SameMessage;
use crate::dccl_cmd::{moved_time_fields, moved_times, Definitions};
use crate::CliError;

/// The loaded DCCL types and their forms.
pub struct Commander {
    codec: Codec,
    types: Vec<String>,
    descriptors: HashMap<String, MessageDescriptor>,
}

pub use gobyd_protocol::message_json;

impl Commander {
    /// Loads every valid DCCL type of the `-f` files (each skipped one is
    /// named on `stderr` with its reason).
    pub(crate) fn load(defs: &Definitions, stderr: &mut dyn Write) -> Result<Self, CliError> {
        let mut codec = defs.new_codec(None, false)?;
        let types = defs.load_valid(&mut codec, stderr)?;
        let descriptors = types
            .iter()
            .filter_map(|t| codec.descriptor(t).map(|d| (t.clone(), d)))
            .collect();
        Ok(Commander {
            codec,
            types,
            descriptors,
        })
    }

    /// A commander with no types (a replay, which sends nothing).
    pub(crate) fn none() -> Self {
        Commander {
            codec: Codec::default(),
            types: Vec::new(),
            descriptors: HashMap::new(),
        }
    }

    /// The names of the loaded types, sorted.
    pub fn types(&self) -> &[String] {
        &self.types
    }

    /// The forms of every loaded type, in the order of [`Commander::types`].
    pub fn forms(&self) -> Value {
        self.types
            .iter()
            .filter_map(|t| self.descriptors.get(t))
            .map(message_form)
            .collect()
    }

    /// The message `msg` (proto3 JSON) of type `type_name`, parsed.
    pub fn parse(&self, type_name: &str, msg: &Value) -> Result<DynamicMessage, String> {
        let desc = self.descriptors.get(type_name).ok_or_else(|| {
            format!(
                "{type_name} is not among the types loaded ({})",
                self.types.join(", ")
            )
        })?;
        gobyd::json::message_of_json(type_name, desc.clone(), msg.clone())
    }

    /// What sending `msg` of type `type_name` would do: `{"ok": true,
    /// "bytes": N, "max_bytes": M, "hex", "changes": [{"field", "reason"}],
    /// "moved": [TEXT], "rounded": [{"field", "given", "sent"}], "sent":
    /// MSG, "back": MSG}`, or `{"ok": false, "error": TEXT}` when it cannot
    /// be encoded (a field of the wrong kind, a required field missing, ...).
    ///
    /// `changes`: values out of range, strings and arrays truncated, ...
    /// (the codec's changes, by field path such as `waypoint[1].x`);
    /// `moved`: times more than 12 hours from this machine's clock, which
    /// decode on another day; `rounded`: every other number the receiver
    /// decodes differently, rounded to its field's precision, with the value
    /// given and the value sent (JSON numbers, 64-bit integers as strings
    /// as in proto3 JSON); `sent`: the message as given; `back`: as its
    /// receiver decodes it.
    pub fn check(&self, type_name: &str, msg: &Value) -> Value {
        let parsed = match self.parse(type_name, msg) {
            Ok(m) => m,
            Err(e) => return json!({"ok": false, "error": e}),
        };
        let mut bytes = Vec::new();
        let options = dccl::EncodeOptions::with_changes();
        let changes = match self.codec.encode_with(&parsed, &mut bytes, &options) {
            Ok(done) => done.changes,
            Err(e) => return json!({"ok": false, "error": e.to_string()}),
        };
        let back = self
            .codec
            .decode_with(&bytes, &dccl::DecodeOptions::as_type(type_name))
            .map(|d| message_json(&d.message))
            .unwrap_or(Value::Null);
        let sent = message_json(&parsed);
        let mut said: Vec<String> = changes.iter().map(|c| c.field.clone()).collect();
        said.extend(
            moved_time_fields(&self.codec, &parsed, &bytes)
                .into_iter()
                .map(|(path, _, _)| path),
        );
        let mut rounded = Vec::new();
        collect_rounded("", &sent, &back, &said, &mut rounded);
        let max_bytes = self.codec.max_size(type_name).ok();
        json!({
            "ok": true,
            "bytes": bytes.len(),
            "max_bytes": max_bytes,
            "hex": hex::encode(&bytes),
            "changes": changes
                .iter()
                .map(|c| json!({"field": c.field, "reason": c.reason}))
                .collect::<Vec<_>>(),
            "moved": moved_times(&self.codec, &parsed, &bytes),
            "rounded": rounded,
            "sent": sent,
            "back": back,
        })
    }

    /// Whether two JSON forms are the same message of a loaded type (as
    /// published, and as a gateway's queue writes it back); plain equality
    /// for other types.
    pub fn same_message(&self) -> SameMessage {
        let descriptors = self.descriptors.clone();
        Box::new(move |type_name: &str, a: &Value, b: &Value| {
            if a == b {
                return true;
            }
            let Some(desc) = descriptors.get(type_name) else {
                return false;
            };
            match (
                DynamicMessage::deserialize(desc.clone(), a),
                DynamicMessage::deserialize(desc.clone(), b),
            ) {
                (Ok(a), Ok(b)) => a == b,
                _ => false,
            }
        })
    }
}

/// A number of a message's proto3 JSON: a JSON number, or a 64-bit
/// integer written as a string.
fn number(value: &Value) -> Option<f64> {
    match value {
        Value::Number(n) => n.as_f64(),
        Value::String(s) => s.parse::<i128>().ok().map(|i| i as f64),
        _ => None,
    }
}

/// Adds to `out` `{"field", "given", "sent"}` for each number of `given`
/// (a message's proto3 JSON; nested messages and repeated fields
/// included, paths as `waypoint[0].x`) that `back` (as decoded) has with
/// another value, but for the paths in `said` (changes already reported).
fn collect_rounded(path: &str, given: &Value, back: &Value, said: &[String], out: &mut Vec<Value>) {
    match (given, back) {
        (Value::Object(a), Value::Object(b)) => {
            for (key, a) in a {
                let p = if path.is_empty() {
                    key.clone()
                } else {
                    format!("{path}.{key}")
                };
                if let Some(b) = b.get(key) {
                    collect_rounded(&p, a, b, said, out);
                }
            }
        }
        (Value::Array(a), Value::Array(b)) => {
            for (i, (a, b)) in a.iter().zip(b).enumerate() {
                collect_rounded(&format!("{path}[{i}]"), a, b, said, out);
            }
        }
        _ => {
            let (Some(x), Some(y)) = (number(given), number(back)) else {
                return;
            };
            // Not the last bits of a double's decimal form.
            let rounded = (x - y).abs() > 1e-9 * x.abs().max(1.0);
            if rounded && !said.iter().any(|s| s == path) {
                out.push(json!({"field": path, "given": given, "sent": back}));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dccl_cmd::ProtoArgs;

    fn commander() -> Commander {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../protos/proto");
        let defs = Definitions::compile(&ProtoArgs {
            file: vec![dir.join("goby/example/navigation.proto")],
            include: vec![],
            arithmetic_models: None,
        })
        .unwrap();
        Commander::load(&defs, &mut Vec::new()).unwrap()
    }

    #[test]
    fn a_draft_is_checked_with_what_the_codec_changes() {
        let c = commander();
        assert_eq!(
            c.types(),
            ["goby.example.Command", "goby.example.NavigationReport"]
        );
        let ok = c.check(
            "goby.example.Command",
            &json!({"destination": 2, "action": "GOTO", "waypoint": [{"x": 10.4, "y": -3}], "note": "survey A"}),
        );
        assert_eq!(ok["ok"], true, "{ok}");
        assert_eq!(ok["changes"].as_array().unwrap().len(), 0, "{ok}");
        // Rounded to its precision: the receiver gets 10.
        assert_eq!(ok["back"]["waypoint"][0]["x"], 10.0, "{ok}");
        let changed = c.check(
            "goby.example.Command",
            &json!({"destination": 2, "action": "HOLD", "note": "a note longer than ten"}),
        );
        let changes = changed["changes"].as_array().unwrap();
        assert_eq!(changes.len(), 1, "{changed}");
        assert_eq!(changes[0]["field"], "note");
        assert_eq!(changed["back"]["note"], "a note lon");
        let bad = c.check("goby.example.Command", &json!({"destination": "two"}));
        assert_eq!(bad["ok"], false);
        assert!(
            bad["error"]
                .as_str()
                .unwrap()
                .contains("goby.example.Command: field destination: invalid digit"),
            "{bad}"
        );
        let missing = c.check("goby.example.Command", &json!({"destination": 2}));
        assert_eq!(missing["ok"], false, "{missing}");
        let unknown = c.check("goby.example.Nothing", &json!({}));
        assert!(
            unknown["error"].as_str().unwrap().contains("not among"),
            "{unknown}"
        );
    }

    #[test]
    fn a_draft_is_checked_with_the_values_rounded_to_their_precision() {
        let c = commander();
        let rounded = c.check(
            "goby.example.Command",
            &json!({"destination": 2, "action": "GOTO", "note": "a note longer than ten",
                    "waypoint": [{"x": 10.4, "y": -3}, {"x": 99999, "y": 7.5}]}),
        );
        assert_eq!(rounded["ok"], true, "{rounded}");
        // Rounded: named with what was given and what is sent. Out of
        // range or truncated: in `changes` only.
        assert_eq!(
            rounded["rounded"],
            json!([
                {"field": "waypoint[0].x", "given": 10.4, "sent": 10.0},
                {"field": "waypoint[1].y", "given": 7.5, "sent": 8.0},
            ]),
            "{rounded}"
        );
        let fields: Vec<&str> = rounded["changes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c["field"].as_str().unwrap())
            .collect();
        assert_eq!(fields, ["waypoint[1].x", "note"], "{rounded}");
        let report = c.check(
            "goby.example.NavigationReport",
            &json!({"source": 1, "destination": 2, "time": 1.0e9, "x": 12.34, "y": 5.6, "z": -1}),
        );
        assert_eq!(
            report["rounded"],
            json!([{"field": "x", "given": 12.34, "sent": 12.3}]),
            "{report}"
        );
        let exact = c.check(
            "goby.example.Command",
            &json!({"destination": 2, "action": "GOTO", "waypoint": [{"x": 10, "y": -3}]}),
        );
        assert_eq!(exact["rounded"], json!([]), "{exact}");
    }

    #[test]
    fn the_same_message_in_two_forms() {
        let c = commander();
        let same = c.same_message();
        assert!(same(
            "goby.example.Command",
            &json!({"destination": 2, "action": "GOTO", "waypoint": [{"x": 1, "y": 2}]}),
            &json!({"action": 1, "waypoint": [{"y": 2.0, "x": 1.0}], "destination": 2})
        ));
        assert!(!same(
            "goby.example.Command",
            &json!({"destination": 2, "action": "GOTO"}),
            &json!({"action": "HOLD", "destination": 2})
        ));
    }
}
