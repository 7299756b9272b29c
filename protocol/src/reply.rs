//! What the daemon answers: exactly one reply to each request line, in the
//! order of the requests, numbered.

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::event::Transfer;
use crate::request::Topic;

/// A reply, without its number ([`Numbered`] adds it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Reply {
    /// To `publish`: the message is on disk (or was delivered to this
    /// node).
    Accepted(Accepted),
    /// To `subscribe`: every topic the client now receives.
    Subscribed {
        /// The topics, by name.
        subscribed: Vec<Topic>,
    },
    /// To `driver_specific`: the request was taken; it runs at this node's
    /// next slot.
    DriverSpecific {
        /// The request's type.
        driver_specific: String,
    },
    /// To `file_send`: the file is on its way.
    FileSend {
        /// The transfer's client id.
        file_send: u64,
        /// The same file to the same node was under way: the request
        /// joined its transfer.
        joined: bool,
        /// The transfer as it stands.
        transfer: Transfer,
    },
    /// To `file_get`: the request went out; the transfer that answers it
    /// names it (`"request": R`).
    FileGet {
        /// The request's number.
        file_get: u16,
        /// The node asked.
        node: i32,
    },
    /// To `transfers`: the transfers under way.
    Transfers {
        /// Each transfer as it stands.
        transfers: Vec<Transfer>,
    },
    /// To `ctd`: the samples taken (all of them; a bad one refuses the
    /// line, naming it).
    Ctd {
        /// How many.
        ctd: usize,
    },
    /// To `nav`: the position taken.
    Nav {
        /// The position.
        nav: crate::forecast::Point,
    },
    /// To `forecast`: seconds until the forecast is made (0: now; later
    /// when the last was made less than the minimum interval ago).
    Forecast {
        /// Seconds.
        forecast: f64,
    },
    /// To `mac_update` (the cycle after it) and `mac_cycle` (the cycle as
    /// it stands): a `goby.acomms.protobuf.MACCycle`, proto3 JSON
    /// (`slot`, `running`, `modem_id`).
    MacCycle {
        /// The cycle.
        mac_cycle: Value,
    },
    /// To `mac_switch`: which MAC of the switcher runs after it.
    MacSwitch {
        /// Which runs.
        mac_switch: crate::mac_switch::MacSwitchState,
    },
    /// To a line that was not taken: why (bad JSON, unknown type, a value
    /// the codec would change, a line over 1 MiB, ...).
    Error {
        /// The reason, in words.
        error: String,
    },
}

impl Reply {
    /// The `error` reply.
    pub fn error(reason: impl Into<String>) -> Self {
        Reply::Error {
            error: reason.into(),
        }
    }

    /// Numbered `number`.
    pub fn numbered(self, number: u64) -> Numbered {
        Numbered {
            reply: self,
            number,
        }
    }
}

/// The reply to a `publish` the daemon took.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Accepted {
    /// The message's type.
    pub accepted: String,
    /// Its id in the daemon's journal (`None`: addressed to this node,
    /// delivered at once); the events about it carry it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<u64>,
    /// Delivered at once to this node, never sent.
    #[serde(default, skip_serializing_if = "crate::is_false")]
    pub delivered: bool,
    /// The messages it pushed out of their full queue.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub dropped: Vec<Dropped>,
    /// The values the codec changed (a type with `clamp_out_of_range`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub changed: Vec<Changed>,
}

/// A message pushed out of its full queue by the one accepted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Dropped {
    /// Its id in the journal (`null`: never journaled).
    pub id: Option<u64>,
    /// Its type.
    pub name: String,
    /// The message.
    pub msg: Value,
}

/// A value the codec changed in a message accepted.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Changed {
    /// The field's path (`waypoint[0].x`).
    pub field: String,
    /// What the codec did, and why.
    pub reason: String,
}

/// A reply with the number of its request line (`"reply": N`, last).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Numbered {
    /// The reply.
    #[serde(flatten)]
    pub reply: Reply,
    /// The number of its request line on the connection (or from the UDP
    /// peer), counted from 1.
    #[serde(rename = "reply")]
    pub number: u64,
}

impl Numbered {
    /// Its line, without the newline.
    pub fn line(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn a_reply_ends_with_its_number_and_reads_back() {
        let accepted = Reply::Accepted(Accepted {
            accepted: "goby.example.Command".into(),
            id: Some(4),
            delivered: false,
            dropped: vec![Dropped {
                id: None,
                name: "goby.example.Command".into(),
                msg: json!({"destination": 2}),
            }],
            changed: Vec::new(),
        })
        .numbered(2);
        let line = accepted.line();
        assert_eq!(
            line,
            r#"{"accepted":"goby.example.Command","id":4,"dropped":[{"id":null,"name":"goby.example.Command","msg":{"destination":2}}],"reply":2}"#
        );
        assert_eq!(serde_json::from_str::<Numbered>(&line).unwrap(), accepted);
        let error = Reply::error("bad").numbered(3);
        assert_eq!(error.line(), r#"{"error":"bad","reply":3}"#);
        assert_eq!(
            serde_json::from_str::<Numbered>(&error.line()).unwrap(),
            error
        );
    }
}
