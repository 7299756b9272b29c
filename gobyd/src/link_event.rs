//! What the daemon's core tells embedded interfaces about the link itself
//! (as opposed to the queue's events): the driver's state, the medium
//! access slots and each reception. The MQTT bridge publishes these.

use std::sync::Arc;

use modemdriver::DriverStatus;
use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::ModemTransmission;
use serde_json::Value;

use crate::json_protocol::message_json;

/// An event of the acoustic link.
#[derive(Debug, Clone)]
pub enum LinkEvent {
    /// The driver reported a fault, a recovery, or that it is ready.
    Driver(Arc<DriverStatus>),
    /// A medium access slot began; the transmission this node initiates in
    /// it, if any (`None`: the slot belongs to another node).
    Slot(Option<Arc<ModemTransmission>>),
    /// The modem received a transmission (its frames are decoded into
    /// queue events right after); `time` is microseconds since the UNIX
    /// epoch.
    Received {
        /// The transmission as the driver reports it (source,
        /// destination, rate, frames and any driver statistics).
        transmission: Arc<ModemTransmission>,
        /// When it was received, microseconds since the UNIX epoch.
        time: i64,
    },
}

/// A reception's summary as the interfaces show it with each message it
/// carried (JSON `"link"`, MQTT `link` and `rx/TYPE`): every field of the
/// transmission in proto JSON form (source, destination, rate, ack wanted,
/// and, from a WHOI Micro-Modem, `receive_stat` with the modem's `$CACST`
/// statistics: SNR in and out, Doppler, data quality factor, bad frames
/// ...) except the frames' bytes, replaced by their count `frames`, and
/// `time` in seconds since the UNIX epoch (`time_micros`: microseconds).
pub fn reception_summary(t: &ModemTransmission, time_micros: i64) -> Value {
    let mut value = message_json(&t.transcode_to_dynamic());
    if let Value::Object(map) = &mut value {
        map.remove("frame");
        map.insert("frames".into(), t.frame.len().into());
        map.insert("time".into(), (time_micros as f64 / 1e6).into());
    }
    value
}
