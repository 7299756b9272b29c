//! What a command of the layer above asks of a driver ([`asked`]), and
//! the work waiting its turn ([`queue_data`], [`queue_first`]).

use std::collections::VecDeque;

use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::{modem_transmission::TransmissionType, ModemTransmission};

use super::Outputs;
use crate::driver::{Acknowledgement, DriverCommand, DriverStatus};

/// Data transmissions waiting at most; beyond, the oldest is dropped: while
/// the modem is busy or away, slot requests must not pile up and then run
/// back to back.
pub const MAX_PENDING_TRANSMISSIONS: usize = 2;

/// What a command asks.
#[derive(Debug)]
pub enum Asked<S> {
    /// A data transmission (its `src` this node's when it had none).
    Data(ModemTransmission),
    /// A `DRIVER_SPECIFIC` transmission (a MAC slot).
    Slot(ModemTransmission),
    /// A driver-specific request of the driver's type `S`.
    Specific(S),
    /// Acknowledge frames received.
    Acknowledge(Acknowledgement),
    /// Nothing the driver does: already reported
    /// ([`DriverStatus::Unsupported`]).
    Nothing,
}

/// What `command` asks of a driver whose node is `modem_id` and whose
/// driver-specific requests are of type `S`. A transmission of another
/// type than data or driver-specific, or a request of another type than
/// `S`, is reported unsupported; `acks` says why the driver takes no
/// `ACK` transmissions (`the Popoto driver sends acks itself`).
pub fn asked<S: ReflectMessage + Default>(
    command: DriverCommand,
    modem_id: i32,
    acks: &str,
    out: &mut Outputs,
) -> Asked<S> {
    match command {
        DriverCommand::Initiate(mut mt) => {
            if mt.src.is_none() || mt.src() == -1 {
                mt.src = Some(modem_id);
            }
            match mt.r#type() {
                TransmissionType::Data => Asked::Data(mt),
                TransmissionType::DriverSpecific => Asked::Slot(mt),
                other => {
                    out.status(DriverStatus::Unsupported {
                        message: format!("ModemTransmission.type {other:?} ({acks})"),
                    });
                    Asked::Nothing
                }
            }
        }
        DriverCommand::Specific(message) => {
            let takes = S::default().descriptor();
            match (message.descriptor() == takes)
                .then(|| message.transcode_to::<S>().ok())
                .flatten()
            {
                Some(request) => Asked::Specific(request),
                None => {
                    out.status(DriverStatus::Unsupported {
                        message: message.descriptor().full_name().to_string(),
                    });
                    Asked::Nothing
                }
            }
        }
        DriverCommand::Acknowledge(ack) => Asked::Acknowledge(ack),
        DriverCommand::Stop(_) => Asked::Nothing,
    }
}

/// Queues `job` last; when [`MAX_PENDING_TRANSMISSIONS`] data
/// transmissions (`is_data`) wait already, the oldest is dropped
/// (reported, [`DriverStatus::Skipped`]).
pub fn queue_data<J>(
    pending: &mut VecDeque<J>,
    job: J,
    is_data: impl Fn(&J) -> bool,
    out: &mut Outputs,
) {
    let waiting = pending.iter().filter(|j| is_data(j)).count();
    if waiting >= MAX_PENDING_TRANSMISSIONS {
        if let Some(i) = pending.iter().position(&is_data) {
            pending.remove(i);
            out.status(DriverStatus::Skipped {
                reason: format!(
                    "{waiting} transmissions already wait for the modem; the oldest is dropped"
                ),
            });
        }
    }
    pending.push_back(job);
}

/// Queues `job` before other work, after the jobs of its kind
/// (`same_kind`) already waiting: acknowledgements go first, in order.
pub fn queue_first<J>(pending: &mut VecDeque<J>, job: J, same_kind: impl Fn(&J) -> bool) {
    let at = pending
        .iter()
        .position(|j| !same_kind(j))
        .unwrap_or(pending.len());
    pending.insert(at, job);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::Output;
    use protos::goby::acomms::protobuf::{EvologicsSpecific, PopotoSpecific};

    #[test]
    fn a_command_is_told_for_what_it_asks() {
        let mut out = Outputs::default();
        let data = DriverCommand::Initiate(ModemTransmission::default());
        let Asked::Data(mt) = asked::<PopotoSpecific>(data, 3, "", &mut out) else {
            panic!("data")
        };
        assert_eq!(mt.src(), 3);
        let ack = DriverCommand::Initiate(ModemTransmission {
            r#type: Some(TransmissionType::Ack as i32),
            ..Default::default()
        });
        assert!(matches!(
            asked::<PopotoSpecific>(ack, 3, "sent by the driver", &mut out),
            Asked::Nothing
        ));
        let other = DriverCommand::Specific(EvologicsSpecific::default().transcode_to_dynamic());
        assert!(matches!(
            asked::<PopotoSpecific>(other, 3, "", &mut out),
            Asked::Nothing
        ));
        let said: Vec<String> = out
            .take()
            .into_iter()
            .map(|o| match o {
                Output::Event(crate::DriverEvent::Status(s)) => s.to_string(),
                other => panic!("{other:?}"),
            })
            .collect();
        assert!(
            said[0].ends_with("ModemTransmission.type Ack (sent by the driver)"),
            "{said:?}"
        );
        assert!(
            said[1].ends_with("goby.acomms.protobuf.EvologicsSpecific"),
            "{said:?}"
        );
    }

    #[test]
    fn the_oldest_data_is_dropped_and_acks_go_first() {
        let mut out = Outputs::default();
        let mut pending = VecDeque::new();
        for job in ["ack", "data1", "data2", "data3"] {
            queue_data(&mut pending, job, |j| j.starts_with("data"), &mut out);
        }
        assert_eq!(pending, ["ack", "data2", "data3"]);
        assert_eq!(out.take().len(), 1);
        queue_first(&mut pending, "ack2", |j| j.starts_with("ack"));
        assert_eq!(pending, ["ack", "ack2", "data2", "data3"]);
    }
}
