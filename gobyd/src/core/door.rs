//! Values checked at the door: a published message that the DCCL codec would
//! change on the way out (a number out of its field's range, NaN, a string,
//! bytes or an array over its limit, an undefined enum value, a value its
//! dynamic conditions leave out or bound more tightly, an unset field they
//! make required) is refused with an error naming the field and the bound
//! or the condition, unless its queue entry sets
//! `clamp_out_of_range: true`. Then it is accepted as libdccl sends it, and
//! the changes are handed back to be reported to the client and logged.
//!
//! A dynamic condition that cannot be evaluated refuses the message
//! whatever the queue entry says, naming the field and the script.
//!
//! The message that goes on (into the journal, the queue and the raw log) is
//! the one the receiver will decode, never the value before it was changed,
//! and it goes on with its DCCL encoding, made here: the journal keeps those
//! bytes and the queue sends them, without encoding the message again.
//!
//! A time coded with `dccl.time` more than half its span (`num_days` days,
//! one by default: 12 h) from now is refused, clamping or not: the codec
//! sends the time of day and the receiver restores the date nearest its
//! own clock, so the message would arrive moved by whole days.

use std::collections::HashSet;
use std::sync::Arc;

use dccl::{Codec, ValueChange};
use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::QueueManagerConfig;

/// A message let through the door.
#[derive(Debug, Clone)]
pub struct Admitted {
    /// The message as it will be sent (changed when `changes` is not empty).
    pub message: DynamicMessage,
    /// Its DCCL encoding: the bytes that will be sent.
    pub encoded: Vec<u8>,
    /// The values the codec changed (empty: sent as published).
    pub changes: Vec<ValueChange>,
}

/// The check of published messages against their DCCL definitions.
#[derive(Debug, Clone)]
pub struct Door {
    codec: Arc<Codec>,
    /// Types whose out-of-range values are clamped rather than refused.
    clamp: HashSet<String>,
    /// Codecs of their own that turn a clamped message into the message the
    /// receiver decodes (encoder, decoder): adaptive arithmetic models
    /// advance with each use, so the daemon's codec is never used for this.
    clamp_codecs: Option<Arc<(Codec, Codec)>>,
}

impl Door {
    /// The door for `codec` (only checked against, never changed), clamping
    /// the types whose queue entry sets `clamp_out_of_range`; `fresh` makes
    /// another codec with the same definitions, asked for twice if any type
    /// clamps.
    pub fn new(codec: Arc<Codec>, queue: &QueueManagerConfig, fresh: impl Fn() -> Codec) -> Self {
        let clamp: HashSet<String> = queue
            .message_entry
            .iter()
            .filter(|e| e.clamp_out_of_range())
            .map(|e| e.protobuf_name.clone())
            .collect();
        let clamp_codecs = (!clamp.is_empty()).then(|| Arc::new((fresh(), fresh())));
        Self {
            codec,
            clamp,
            clamp_codecs,
        }
    }

    /// Checks `message` by encoding it: unchanged, it passes as it is (with
    /// its encoding); changed by the codec, it is refused (the error names
    /// each field, its value and the bound) or, for a clamping type, passed
    /// on as it will be sent.
    pub fn admit(&self, message: DynamicMessage) -> Result<Admitted, String> {
        let descriptor = message.descriptor();
        let name = descriptor.full_name();
        // A time the receiver would restore on another date is refused
        // whatever the queue entry says: moving it by whole days is no
        // clamp to a bound.
        let moved = self
            .codec
            .moved_dates(&message)
            .map_err(|e| e.to_string())?;
        if !moved.is_empty() {
            let fields: Vec<String> = moved
                .iter()
                .map(|c| format!("field {}: {}", c.field, c.reason))
                .collect();
            return Err(format!("{name} refused: {}", fields.join("; ")));
        }
        // The one encoding of the message (the daemon's codec has no
        // adaptive model that encoding would advance: the configuration
        // check refuses them).
        let mut encoded = Vec::new();
        let changes = self
            .codec
            .encode_with(&message, &mut encoded, &dccl::EncodeOptions::with_changes())
            .map_err(|e| e.to_string())?
            .changes;
        if changes.is_empty() {
            return Ok(Admitted {
                message,
                encoded,
                changes,
            });
        }
        if !self.clamp.contains(name) {
            let fields: Vec<String> = changes
                .iter()
                .map(|c| format!("field {}: {}", c.field, would(&c.reason)))
                .collect();
            return Err(format!(
                "{name} refused: {} (set clamp_out_of_range: true in its queue entry to send {} so)",
                fields.join("; "),
                if changes.len() == 1 { "it" } else { "them" }
            ));
        }
        // As the receiver will decode it.
        let (encoder, decoder) = self
            .clamp_codecs
            .as_deref()
            .map(|(e, d)| (e, d))
            .ok_or_else(|| format!("{name}: no codec to clamp with"))?;
        let bytes = encoder.encode(&message).map_err(|e| e.to_string())?;
        let sent = decoder
            .decode(&bytes)
            .map_err(|e| format!("{name}: the clamped message does not decode: {e}"))?;
        Ok(Admitted {
            message: sent,
            encoded: bytes,
            changes,
        })
    }
}

/// A change as the codec reports it (`WHAT: ACTION`, the action done:
/// "sent as the minimum 0 (the field is required)", "truncated") told as
/// what the codec would do to a message that is refused, so not sent:
/// `WHAT, which the codec would send as the minimum 0 (...)`; an action
/// not known here is told as a change (`WHAT: the codec would change it
/// (ACTION)`).
fn would(reason: &str) -> String {
    let Some((what, action)) = reason.rsplit_once(": ") else {
        return format!("the codec would change it ({reason})");
    };
    let verbs = [
        ("not sent", "not send"),
        ("sent as", "send as"),
        ("truncated", "truncate"),
        ("padded", "pad"),
    ];
    match verbs.iter().find(|(done, _)| action.starts_with(done)) {
        Some((done, doing)) => format!(
            "{what}, which the codec would {doing}{}",
            &action[done.len()..]
        ),
        None => format!("{what}: the codec would change it ({action})"),
    }
}

#[cfg(test)]
mod tests {
    use protos::goby::acomms::protobuf::QueuedMessageEntry;
    use protos::goby::example::{Command, Waypoint};

    use super::*;

    fn codec() -> Codec {
        let mut codec = Codec::new();
        codec.load_type::<Command>().unwrap();
        codec
    }

    fn door(clamp: bool) -> Door {
        let queue = QueueManagerConfig {
            message_entry: vec![QueuedMessageEntry {
                protobuf_name: "goby.example.Command".into(),
                clamp_out_of_range: Some(clamp),
                ..Default::default()
            }],
            ..Default::default()
        };
        Door::new(Arc::new(codec()), &queue, codec)
    }

    fn command(destination: i32, x: f64, note: &str) -> DynamicMessage {
        Command {
            destination,
            action: 1,
            waypoint: vec![Waypoint { x, y: 0.0 }],
            note: Some(note.into()),
        }
        .transcode_to_dynamic()
    }

    #[test]
    fn values_the_codec_keeps_pass_as_they_are_with_their_encoding() {
        let admitted = door(false).admit(command(2, 100.0, "ok")).unwrap();
        assert!(admitted.changes.is_empty());
        assert_eq!(admitted.message, command(2, 100.0, "ok"));
        assert_eq!(
            admitted.encoded,
            codec().encode(&command(2, 100.0, "ok")).unwrap()
        );
    }

    #[test]
    fn out_of_range_nan_and_long_values_are_refused_naming_field_and_bound() {
        let door = door(false);
        let err = door.admit(command(99, 0.0, "ok")).unwrap_err();
        // Said as what the codec would do to the value, not as if sent.
        assert!(
            err.contains(
                "goby.example.Command refused: field destination: 99 is out of range [0, 31], \
                 which the codec would send as the minimum 0 (the field is required) \
                 (set clamp_out_of_range: true in its queue entry to send it so)"
            ),
            "{err}"
        );
        assert!(!err.contains(": sent as"), "{err}");
        let err = door.admit(command(2, 120_000.0, "ok")).unwrap_err();
        assert!(err.contains("field waypoint[0].x"), "{err}");
        assert!(err.contains("10000"), "{err}");
        let err = door.admit(command(2, f64::NAN, "ok")).unwrap_err();
        assert!(err.contains("waypoint[0].x"), "{err}");
        let err = door
            .admit(command(2, 0.0, &"n".repeat(60_000)))
            .unwrap_err();
        assert!(
            err.contains(
                "field note: string of 60000 bytes longer than max_length 10, which the codec \
                 would truncate"
            ),
            "{err}"
        );
        assert!(err.len() < 2_000, "the error does not repeat the value");
    }

    #[test]
    fn every_change_is_told_as_what_the_codec_would_do() {
        for (reason, told) in [
            (
                "99 is out of range [0, 31]: sent as not present",
                "99 is out of range [0, 31], which the codec would send as not present",
            ),
            (
                "NaN: sent as the minimum -100",
                "NaN, which the codec would send as the minimum -100",
            ),
            (
                "7 elements over max_repeat 4: truncated",
                "7 elements over max_repeat 4, which the codec would truncate",
            ),
            (
                "3 is not the static value 4: not sent (received as the static value)",
                "3 is not the static value 4, which the codec would not send (received as the static value)",
            ),
            ("odd: reshaped", "odd: the codec would change it (reshaped)"),
            ("plain", "the codec would change it (plain)"),
        ] {
            assert_eq!(would(reason), told);
        }
    }

    #[test]
    fn a_time_the_receiver_would_move_by_days_is_refused_naming_message_and_field() {
        use protos::goby::example::NavigationReport;
        let nav_codec = || {
            let mut codec = Codec::new();
            codec.load_type::<NavigationReport>().unwrap();
            codec
        };
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_secs() as f64;
        let report = |time: f64| {
            NavigationReport {
                source: 1,
                destination: 2,
                time,
                ..Default::default()
            }
            .transcode_to_dynamic()
        };
        for clamp in [false, true] {
            let queue = QueueManagerConfig {
                message_entry: vec![QueuedMessageEntry {
                    protobuf_name: "goby.example.NavigationReport".into(),
                    clamp_out_of_range: Some(clamp),
                    ..Default::default()
                }],
                ..Default::default()
            };
            let door = Door::new(Arc::new(nav_codec()), &queue, nav_codec);
            // Within half a day of now: as sent.
            for time in [now, now - 11.0 * 3600.0, now + 3600.0] {
                let admitted = door.admit(report(time)).unwrap();
                assert!(admitted.changes.is_empty());
            }
            // Further: the receiver would restore it a day or more off,
            // which no clamping makes right.
            for (time, days) in [
                (now - 2.25 * 86_400.0, "2 days later"),
                (now + 13.0 * 3600.0, "1 day earlier"),
            ] {
                let err = door.admit(report(time)).unwrap_err();
                for part in [
                    "goby.example.NavigationReport refused: field time:",
                    days,
                    "give a time within 12 h of now",
                ] {
                    assert!(err.contains(part), "{part:?} missing from {err}");
                }
            }
        }
    }

    #[test]
    fn a_clamping_type_passes_as_it_will_be_sent_with_its_changes() {
        let admitted = door(true)
            .admit(command(2, 0.0, "a note much too long"))
            .unwrap();
        assert_eq!(admitted.changes.len(), 1);
        assert_eq!(admitted.changes[0].field, "note");
        assert_eq!(
            admitted.message.get_field_by_name("note").unwrap().as_str(),
            Some("a note muc")
        );
        // The encoding sent is the clamped message's.
        assert_eq!(admitted.encoded, codec().encode(&admitted.message).unwrap());
    }

    #[test]
    fn a_publish_that_breaks_a_dynamic_condition_is_refused_with_the_reason() {
        let pool = dccl::compile_sources(&[(
            "survey.proto",
            r#"syntax = "proto2";
               import "dccl/option_extensions.proto";
               package survey;
               message Leg {
                 option (dccl.msg) = { id: 40 max_bytes: 16 codec_version: 4 };
                 enum Mode { IDLE = 1; LINE = 2; }
                 required Mode mode = 1;
                 optional int32 heading = 2 [(dccl.field) = { min: 0 max: 359
                     dynamic_conditions { only_if: "this.mode == 'LINE'" } }];
                 optional int32 depth = 3 [(dccl.field) = { min: 0 max: 100
                     dynamic_conditions { max: "this.mode == 'LINE' and 10 or 100" } }];
                 optional int32 speed = 4 [(dccl.field) = { min: 0 max: 10
                     dynamic_conditions { omit_if: "this.depth > 50" } }];
               }"#,
        )])
        .unwrap();
        let desc = pool.get_message_by_name("survey.Leg").unwrap();
        let codec = || {
            let mut codec = Codec::new();
            codec.load(&desc).unwrap();
            codec
        };
        let door = Door::new(Arc::new(codec()), &QueueManagerConfig::default(), codec);
        let leg = |text: &str| DynamicMessage::parse_text_format(desc.clone(), text).unwrap();
        // A field its condition leaves out.
        let err = door
            .admit(leg("mode: IDLE heading: 90 depth: 5"))
            .unwrap_err();
        assert!(
            err.contains(
                "survey.Leg refused: field heading: only_if \"this.mode == 'LINE'\" is false, \
                 which the codec would not send (the condition leaves the field out)"
            ),
            "{err}"
        );
        // A value outside its dynamic bounds.
        let err = door
            .admit(leg("mode: LINE heading: 90 depth: 50"))
            .unwrap_err();
        assert!(
            err.contains("field depth: 50 is out of range [0, 10]"),
            "{err}"
        );
        // A condition that cannot be evaluated (no depth to compare): the
        // script and why.
        let err = door
            .admit(leg("mode: LINE heading: 90 speed: 3"))
            .unwrap_err();
        assert!(
            err.contains("field speed") && err.contains("this.depth > 50") && err.contains("nil"),
            "{err}"
        );
        // Within its conditions: as published.
        let admitted = door.admit(leg("mode: LINE heading: 90 depth: 5")).unwrap();
        assert!(admitted.changes.is_empty());
    }
}
