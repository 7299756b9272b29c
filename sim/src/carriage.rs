//! Which publications each data packet carried, from a node's own events:
//! the queue places messages in frames ([`QueueEvent::Sent`]) when the
//! driver asks for data, and the driver then reports the packet
//! ([`ModemEvent::Transmitted`], its `time` the moment it started). The
//! entries placed since a node's previous data packet are those the next
//! one carried when it was sent; when it was not (it failed, or had
//! nothing), they go back to the queue and are placed again.

use std::collections::HashMap;

use gobyd::event::{DaemonEvent, ModemEvent};
use modemdriver::TransmitOutcome;
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use queue::QueueEvent;

/// The data packets that carried each journal entry; see the
/// [module](self).
#[derive(Debug, Default)]
pub struct Carriage {
    /// Entries placed in frames since the node's last data packet, by node.
    placed: HashMap<usize, Vec<u64>>,
    /// Start times (µs since the UNIX epoch, the sender's clock) of the
    /// packets that carried each (node, journal id), in order.
    packets: HashMap<(usize, u64), Vec<u64>>,
}

impl Carriage {
    /// An event of node `node`.
    pub fn event(&mut self, node: usize, event: &DaemonEvent) {
        match event {
            DaemonEvent::Queue {
                event: QueueEvent::Sent { .. },
                entry: Some(entry),
            } => self.placed.entry(node).or_default().push(*entry),
            DaemonEvent::Modem {
                event:
                    ModemEvent::Transmitted {
                        transmission,
                        outcome,
                    },
                ..
            } if transmission.r#type() == TransmissionType::Data => {
                let placed = self.placed.remove(&node).unwrap_or_default();
                if *outcome != TransmitOutcome::Sent {
                    return;
                }
                let Some(start) = transmission.time else {
                    return;
                };
                for entry in placed {
                    self.packets.entry((node, entry)).or_default().push(start);
                }
            }
            _ => {}
        }
    }

    /// Start times of the packets that carried journal id `entry` of node
    /// `node`, in order (µs since the UNIX epoch, the sender's clock).
    pub fn packets(&self, node: usize, entry: u64) -> &[u64] {
        self.packets.get(&(node, entry)).map_or(&[], Vec::as_slice)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use prost_reflect::ReflectMessage;
    use protos::goby::acomms::protobuf::ModemTransmission;

    fn sent(entry: u64) -> DaemonEvent {
        DaemonEvent::Queue {
            event: QueueEvent::Sent {
                message: protos::goby::example::Command::default().transcode_to_dynamic(),
                id: entry,
                dccl_id: 125,
                frame: 0,
                awaiting_ack: false,
                link: 0,
            },
            entry: Some(entry),
        }
    }

    fn transmitted(time: u64, outcome: TransmitOutcome) -> DaemonEvent {
        DaemonEvent::modem(ModemEvent::Transmitted {
            transmission: ModemTransmission {
                r#type: Some(TransmissionType::Data as i32),
                time: Some(time),
                ..Default::default()
            },
            outcome,
        })
    }

    #[test]
    fn a_packet_carries_what_was_placed_since_the_last_and_a_failed_one_nothing() {
        let mut c = Carriage::default();
        c.event(0, &sent(1));
        c.event(1, &sent(9));
        c.event(0, &sent(2));
        c.event(0, &transmitted(100, TransmitOutcome::Sent));
        c.event(0, &sent(3));
        c.event(0, &transmitted(200, TransmitOutcome::Failed("late".into())));
        c.event(0, &sent(3));
        c.event(0, &sent(1));
        c.event(0, &transmitted(300, TransmitOutcome::Sent));
        assert_eq!(c.packets(0, 1), [100, 300]);
        assert_eq!(c.packets(0, 2), [100]);
        assert_eq!(c.packets(0, 3), [300]);
        // Node 1 sent nothing yet.
        assert_eq!(c.packets(1, 9), [] as [u64; 0]);
    }
}
