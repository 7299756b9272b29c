//! What the daemon's core tells embedded interfaces about the link itself
//! (as opposed to the queue's events): the driver's state, the medium
//! access slots and each reception. The MQTT bridge publishes these.

use std::sync::Arc;

use modemdriver::DriverStatus;
use protos::goby::acomms::protobuf::ModemTransmission;

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
