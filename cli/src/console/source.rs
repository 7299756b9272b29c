//! Where the console reads the fleet from ([`Source`]: an MQTT broker, one
//! gobyd's JSON interface, or the replay of a `goby sim` run) and the
//! commands it hands it ([`Outbound`]); [`feed`](super::feed) runs it.

use serde_json::Value;

use super::mac::MacKind;
use super::replay::{Replay, AUTONOMY};

/// Where the fleet is read from.
#[derive(Debug, Clone, PartialEq)]
pub enum Source {
    /// An MQTT broker, the gateways publishing under `prefix/`.
    Mqtt {
        /// Broker host.
        host: String,
        /// Broker port.
        port: u16,
        /// The topic prefix, without its trailing `/`.
        prefix: String,
    },
    /// One gobyd's JSON interface over TCP, shown as node `node`.
    Json {
        /// `HOST:PORT` of the interface.
        address: String,
        /// The name the node is shown under.
        node: String,
    },
    /// The replay file of a `goby sim` run, played at `warp` times its
    /// virtual time ([`super::replay`]).
    Replay {
        /// The file, as named on the command line.
        path: String,
        /// The file, read.
        replay: Box<Replay>,
        /// Virtual seconds a wall second.
        warp: f64,
    },
}

impl Source {
    /// Words for the page's header and the start-up line.
    pub fn describe(&self) -> String {
        match self {
            Source::Mqtt { host, port, prefix } => {
                format!("the fleet under {prefix}/ on the MQTT broker {host}:{port}")
            }
            Source::Json { address, node } => {
                format!("the JSON interface of gobyd at {address} (its node shown as {node:?})")
            }
            Source::Replay {
                path,
                replay,
                warp,
            } => format!(
                "the replay of the goby sim run in {path} (seed {}, {} nodes, {:.0} s) at {warp}× its time",
                replay.seed,
                replay.nodes.len(),
                replay.end - replay.start
            ),
        }
    }

    /// Where a command of type `type_name` to `node` goes: the node's `tx`
    /// topic, or the JSON interface.
    pub fn topic(&self, node: &str, type_name: &str) -> String {
        match self {
            Source::Mqtt { prefix, .. } => format!("{prefix}/{node}/tx/{type_name}"),
            Source::Json { address, .. } => format!("json {address}"),
            Source::Replay { .. } => AUTONOMY.to_string(),
        }
    }

    /// Where a MAC request of `kind` to `node` goes: the node's
    /// `mac_update` or `mac_switch` topic, or the JSON interface.
    pub fn mac_topic(&self, node: &str, kind: MacKind) -> String {
        match self {
            Source::Mqtt { prefix, .. } => format!("{prefix}/{node}/{}", kind.word()),
            Source::Json { address, .. } => format!("json {address}"),
            Source::Replay { .. } => "replay".to_string(),
        }
    }
}

/// A command for the source to send.
#[derive(Debug, Clone)]
pub struct Outbound {
    /// The command's id on the page.
    pub command: u64,
    /// Where it goes ([`Source::topic`]).
    pub topic: String,
    /// Its type.
    pub type_name: String,
    /// The message, proto3 JSON (for a MAC request: the `MACUpdate` or
    /// the switch).
    pub msg: Value,
    /// A MAC request rather than a message to publish.
    pub mac: Option<MacKind>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sources_are_described_without_a_doubled_word() {
        let json = Source::Json {
            address: "127.0.0.1:11170".into(),
            node: "gobyd".into(),
        };
        assert_eq!(
            json.describe(),
            "the JSON interface of gobyd at 127.0.0.1:11170 (its node shown as \"gobyd\")"
        );
        let mqtt = Source::Mqtt {
            host: "127.0.0.1".into(),
            port: 1883,
            prefix: "fleet".into(),
        };
        assert_eq!(
            mqtt.describe(),
            "the fleet under fleet/ on the MQTT broker 127.0.0.1:1883"
        );
    }
}
