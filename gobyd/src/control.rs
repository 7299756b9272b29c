//! Requests from an autonomy interface to the daemon's core that are not
//! messages: flushing a queue and restarting the modem driver (as
//! pAcommsHandler's `ACOMMS_FLUSH_QUEUE` and `ACOMMS_DRIVER_RESET`).

use tokio::sync::oneshot;

/// A request to the core, with where to send its outcome.
#[derive(Debug)]
pub enum Control {
    /// Empty the queue of a DCCL id; its messages leave the journal.
    FlushQueue {
        /// The DCCL id of the queue's type.
        dccl_id: u32,
        /// How many messages were flushed, or why none could be.
        reply: oneshot::Sender<Result<usize, String>>,
    },
    /// A driver-specific request (e.g. `goby.acomms.protobuf.MicroModemSpecific`
    /// for a ping or a long-baseline interrogation): handed to the driver;
    /// its result comes later as a driver-specific report.
    DriverSpecific {
        /// The request.
        message: prost_reflect::DynamicMessage,
        /// Handed to the driver, or why not.
        reply: oneshot::Sender<Result<(), String>>,
    },
    /// Stop the modem driver and start it again from the configuration.
    ResetDriver {
        /// Done, or why the driver could not start again.
        reply: oneshot::Sender<Result<(), String>>,
    },
    /// A file transfer request for the network layer
    /// ([`crate::network`]).
    Network {
        /// What is asked.
        request: NetworkRequest,
        /// The answer (the JSON reply's fields), or why not.
        reply: oneshot::Sender<Result<serde_json::Value, String>>,
    },
}

/// What a client asks of the network layer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NetworkRequest {
    /// Send the file at `path` (on the daemon's machine) to node `dest`,
    /// named `name` there (its own name when `None`); joins the transfer
    /// of the same file to the same node under way.
    SendFile {
        /// The receiving node.
        dest: i32,
        /// The file.
        path: std::path::PathBuf,
        /// Its name at the receiver.
        name: Option<String>,
    },
    /// Ask node `node` for its file `path` (under its `network.serve_dir`).
    GetFile {
        /// The node asked.
        node: i32,
        /// The path there.
        path: String,
    },
    /// The transfers under way.
    Transfers,
}

/// The DCCL id of a flush request as pAcommsHandler takes it:
/// `@PB[goby.acomms.protobuf.QueueFlush] dccl_id: N`, the text format alone
/// (`dccl_id: N`), or the id as a number.
pub fn parse_flush(value: &str) -> Result<u32, String> {
    let mut text = value.trim();
    if let Some(rest) = text.strip_prefix("@PB[") {
        let (name, body) = rest
            .split_once(']')
            .ok_or("\"@PB[\" without its closing \"]\"")?;
        if name.trim() != "goby.acomms.protobuf.QueueFlush" {
            return Err(format!(
                "expected goby.acomms.protobuf.QueueFlush, not {}",
                name.trim()
            ));
        }
        text = body.trim();
    }
    let number = match text.strip_prefix("dccl_id") {
        Some(rest) => rest.trim_start().strip_prefix(':').unwrap_or(rest).trim(),
        None => text,
    };
    number
        .parse::<u32>()
        .map_err(|_| format!("{value:?}: expected \"dccl_id: N\" with N a DCCL id"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flush_requests_name_their_dccl_id() {
        for value in [
            "@PB[goby.acomms.protobuf.QueueFlush] dccl_id: 125",
            "dccl_id: 125",
            " 125 ",
        ] {
            assert_eq!(parse_flush(value), Ok(125), "{value}");
        }
        assert!(parse_flush("@PB[goby.example.Command] dccl_id: 1")
            .unwrap_err()
            .contains("QueueFlush"));
        assert!(parse_flush("dccl_id: x").unwrap_err().contains("DCCL id"));
    }
}
