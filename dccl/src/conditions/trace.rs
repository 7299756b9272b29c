//! The path a message with dynamic conditions takes through its codecs,
//! step by step, as the sender encodes it and as a receiver decodes it:
//! which fields the conditions leave out, which they make required, the
//! bounds in force, and the bits each field takes. A receiver decodes a
//! frame as it was encoded when it takes the same path; where it does
//! not (a condition reading a value the codec changed, an unset field
//! made required, a field decoded after the condition), the first step
//! that differs tells where and how.

use std::cell::RefCell;

use prost_reflect::FieldDescriptor;

/// One step of coding a message with conditions.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Step {
    /// The fields of a message (or of a part of it) begin.
    Enter,
    /// They end.
    Leave,
    /// Whether the field (or an element of it) is left out.
    Omit(FieldDescriptor, bool),
    /// Whether the field is coded without its "not present" value.
    Required(FieldDescriptor, bool),
    /// The bounds in force (bits of the two doubles).
    Bounds(FieldDescriptor, u64, u64),
    /// An absent message (or element) the sender wrote as zeros, which a
    /// receiver reads as a message.
    Zeros(FieldDescriptor),
    /// A field done, with the bits it took.
    Field(FieldDescriptor, usize),
}

/// The steps taken, in order.
pub(crate) type Trace = RefCell<Vec<Step>>;

/// Records `step` in `trace`, when there is one.
pub(crate) fn step(trace: Option<&Trace>, step: impl FnOnce() -> Step) {
    if let Some(t) = trace {
        t.borrow_mut().push(step());
    }
}

fn name(f: &FieldDescriptor) -> &str {
    f.full_name()
}

/// What the coder did at `step`, for a report.
fn told(step: &Step) -> String {
    match step {
        Step::Enter => "starts a message".to_string(),
        Step::Leave => "ends a message".to_string(),
        Step::Omit(f, true) => format!("leaves {} out", name(f)),
        Step::Omit(f, false) => format!("codes {}", name(f)),
        Step::Required(f, true) => {
            format!("codes {} as required (no \"not present\" value)", name(f))
        }
        Step::Required(f, false) => format!("codes {} as optional", name(f)),
        Step::Bounds(f, min, max) => format!(
            "codes {} within [{}, {}]",
            name(f),
            f64::from_bits(*min),
            f64::from_bits(*max)
        ),
        Step::Zeros(f) => format!("writes zeros for the absent {}", name(f)),
        Step::Field(f, bits) => format!("takes {bits} bit(s) for {}", name(f)),
    }
}

/// Where the receiver's steps (`received`) leave the sender's (`sent`):
/// `None` when they are the same (the steps a receiver takes to read a
/// message the sender wrote as zeros are not compared, their bits are).
pub(crate) fn first_difference(sent: &[Step], received: &[Step]) -> Option<String> {
    let mut j = 0;
    for s in sent {
        if let Step::Zeros(_) = s {
            // The receiver reads a message from the zeros, or nothing.
            if received.get(j) == Some(&Step::Enter) {
                let mut depth = 0usize;
                while let Some(r) = received.get(j) {
                    j += 1;
                    match r {
                        Step::Enter => depth += 1,
                        Step::Leave => depth -= 1,
                        _ => {}
                    }
                    if depth == 0 {
                        break;
                    }
                }
            }
            continue;
        }
        match received.get(j) {
            Some(r) if r == s => j += 1,
            Some(r) => return Some(format!("the sender {}, the receiver {}", told(s), told(r))),
            None => return Some(format!("the sender {}, the receiver stops", told(s))),
        }
    }
    received
        .get(j)
        .map(|r| format!("the sender stops, the receiver {}", told(r)))
}
