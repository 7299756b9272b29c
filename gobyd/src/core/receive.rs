//! The core's side of the receive path and of the events it hands over:
//! a reception goes through the queue, the network layer and
//! [`Delivery`](super::delivery::Delivery); queue events go to the
//! interfaces and the mission log.

use std::sync::Arc;

use modemdriver::ModemTransmission;
use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use queue::{QueueEvent, ReceivedMessage};
use tokio::sync::broadcast;

use protos::goby::acomms::protobuf::MacUpdate;

use super::crash_point::CrashPoint;
use super::delivery::FrameFaults;
use super::Core;
use crate::event::UpdateSource;
use crate::event::{DaemonEvent, LinkSummary, MissionLog, Reception, SharedEvent, TransferEvent};

impl Core {
    /// Logs the queue events and sends them to the clients; returns the
    /// messages dropped from a full queue (journal id, message).
    pub(super) fn forward_queue_events(
        &mut self,
    ) -> Vec<(Option<u64>, prost_reflect::DynamicMessage)> {
        let mut dropped = Vec::new();
        let events = self.outbox.events();
        for (event, entry) in events {
            let Some((event, entry)) = self.network_view(event, entry) else {
                continue;
            };
            if let QueueEvent::Dropped { message, .. } = &event {
                dropped.push((entry, message.clone()));
            }
            self.hand_over(event, entry, &Reception::default());
        }
        dropped
    }

    /// A queue event as the clients see it: events of the network layer's
    /// messages are told as the message they carry, or not at all (see
    /// [`Network::queue_event`]).
    pub(super) fn network_view(
        &mut self,
        event: QueueEvent,
        entry: Option<u64>,
    ) -> Option<(QueueEvent, Option<u64>)> {
        match &mut self.network {
            Some(network) => network.queue_event(event, entry),
            None => Some((event, entry)),
        }
    }

    /// The network layer's timers: what expired without an end-to-end ack
    /// is told.
    pub(super) fn network_tick(&mut self) {
        let now = self.clock.now();
        let Some(network) = &mut self.network else {
            return;
        };
        let receipt = network.tick(now);
        for (event, entry) in receipt.events {
            self.hand_over(event, entry, &Reception::default());
        }
        self.report_transfers(receipt.transfers);
    }

    /// Sends transfers' progress to the interfaces.
    pub(super) fn report_transfers(&self, events: Vec<TransferEvent>) {
        for event in events {
            let _ = self.events.send(Arc::new(DaemonEvent::Transfer(event)));
        }
    }

    /// A transmission from the link: its messages go down the receive path
    /// ([`Delivery::receive`]: recorded, held, handed over), then its
    /// frames are acknowledged (by drivers that ack in software with
    /// `deferred_ack`) as it says.
    pub(super) fn receive(&mut self, i: usize, transmission: ModemTransmission) {
        if transmission.r#type() == TransmissionType::Data && !transmission.frame.is_empty() {
            CrashPoint::Received.reached();
        }
        // Each message handed over carries the reception it came in (and,
        // with several links, the link's name).
        let mut summary = LinkSummary::of(&transmission, self.clock.now());
        if self.several {
            summary.name = Some(self.links[i].name.clone());
        }
        let reception = Reception {
            link: Some(Arc::new(summary)),
            recovered: false,
            route: None,
        };
        let link = reception.link.clone();
        let mut faults = FrameFaults::default();
        for e in self.outbox.receive(&transmission, i) {
            tracing::warn!(src = transmission.src(), "received: {e}");
            faults.note(&e);
        }
        let events = self.outbox.events();
        let mut messages = Vec::new();
        for (event, entry) in events {
            match event {
                QueueEvent::Received(received) => messages.push(received),
                QueueEvent::OwnBroadcastHeard {
                    message,
                    heard_from,
                    ..
                } => tracing::warn!(
                    src = heard_from,
                    "received {} from node {heard_from} with this node ({}) as its source, broadcast: \
                     not delivered (a node's own broadcast is not handed back to it); node \
                     {heard_from} sent a message in this node's name",
                    message.descriptor().full_name(),
                    self.modem_id
                ),
                event => {
                    if let Some((event, entry)) = self.network_view(event, entry) {
                        self.hand_over(event, entry, &Reception::default())
                    }
                }
            }
        }
        let now = self.clock.now();
        // The network layer's messages: forwarded (journaled first),
        // unwrapped for this node, or acks.
        let receipt = self
            .network
            .as_mut()
            .map(|n| n.receive(messages.split_off(0), &mut self.outbox, now));
        if let Some(receipt) = &receipt {
            messages = receipt.plain.clone();
            if receipt.refuse_ack {
                faults.unplaced = true;
            }
            for (event, entry) in receipt.events.clone() {
                self.hand_over(event, entry, &Reception::default());
            }
            for dropped in receipt.route_drops.clone() {
                let event = Arc::new(DaemonEvent::RouteDropped(dropped));
                let _ = self.events.send(event.clone());
                if let Some(log) = &mut self.mission_log {
                    log.event(now, &event, None);
                }
            }
            self.report_transfers(receipt.transfers.clone());
            for arrived in &receipt.arrived {
                let routed = Reception {
                    link: link.clone(),
                    recovered: false,
                    route: arrived.route.clone().map(Into::into),
                };
                let on_record = self.delivery.record(
                    vec![arrived.received.clone()],
                    &routed,
                    u64::try_from(now).unwrap_or(0),
                    tokio::time::Instant::now(),
                );
                if !on_record {
                    faults.unplaced = true;
                }
            }
        }
        let taker = self.taker_present();
        let (events, mission_log) = (&self.events, &mut self.mission_log);
        let mut updates = Vec::new();
        let ack = self.delivery.receive(
            transmission,
            messages,
            &faults,
            &reception,
            (u64::try_from(now).unwrap_or(0), tokio::time::Instant::now()),
            taker,
            handing_over(events, mission_log, now, &mut updates),
        );
        self.apply_received_updates(updates);
        if let (Some(network), Some(receipt)) = (&mut self.network, &receipt) {
            network.recorded(receipt, &mut self.outbox, now);
        }
        if let Some(ack) = ack {
            let outcome = self.links[i].driver.as_ref().map(|d| d.acknowledge(ack));
            if let Some(Err(e)) = outcome {
                tracing::error!("cannot acknowledge: {e}");
            }
        }
    }

    /// Whether a received message handed over now reaches the autonomy
    /// side: a bridge or the UDP interface takes every message, or someone
    /// listens to the events (without those, the only listeners are the
    /// connected TCP JSON clients and the embedding program's
    /// [`subscribe`](Self::subscribe) receivers; the daemon's own receivers,
    /// the core's and the link forecast's, are not takers).
    pub(super) fn taker_present(&self) -> bool {
        self.always_taken
            || self.events.receiver_count()
                > self
                    .internal_listeners
                    .load(std::sync::atomic::Ordering::SeqCst)
    }

    /// Hands the held messages over once a taker is there (see
    /// [`Delivery::release`]).
    pub(super) fn release_held(&mut self) {
        let taker = self.taker_present();
        let now = self.clock.now();
        let (events, mission_log) = (&self.events, &mut self.mission_log);
        let mut updates = Vec::new();
        self.delivery.release(
            taker,
            tokio::time::Instant::now(),
            u64::try_from(now).unwrap_or(0),
            handing_over(events, mission_log, now, &mut updates),
        );
        self.apply_received_updates(updates);
    }

    /// Applies the `MACUpdate`s handed over that are for this node (each
    /// publication once: a retransmission is not handed over again).
    fn apply_received_updates(&mut self, updates: Vec<MacUpdate>) {
        for update in updates {
            if update.dest == self.modem_id {
                let _ = self.mac_update(&update, UpdateSource::Link);
            }
        }
    }

    /// Hands a queue event over: the event to the clients connected now
    /// and to the bridges (MQTT, MOOS), then its line in the mission
    /// log (the inbox's mark follows that write at once). `reception`: for
    /// a received message, the transmission it came in and whether it is
    /// handed over after a restart.
    /// With several links, a message's sending names its link in the
    /// mission log.
    pub(super) fn hand_over(
        &mut self,
        event: QueueEvent,
        entry: Option<u64>,
        reception: &Reception,
    ) {
        let now = self.clock.now();
        let over = match &event {
            QueueEvent::Sent { link, .. } if self.several => {
                self.links.get(*link).map(|l| l.name.as_str())
            }
            _ => None,
        };
        hand_over(
            &self.events,
            &mut self.mission_log,
            now,
            (event, entry),
            reception,
            over,
        );
    }
}

/// Hands an event over to `events` (the interfaces), then to the mission
/// log (see [`Core::hand_over`]): the log's record is written last, as
/// the inbox marks a received message handed over right after it. `over`:
/// the link a sending went over, for its record in the mission log.
fn hand_over(
    events: &broadcast::Sender<SharedEvent>,
    mission_log: &mut Option<Box<dyn MissionLog>>,
    now: i64,
    (event, entry): (QueueEvent, Option<u64>),
    reception: &Reception,
    over: Option<&str>,
) {
    let event = Arc::new(match event {
        QueueEvent::Received(received) => DaemonEvent::Received {
            received,
            reception: reception.clone(),
        },
        event => DaemonEvent::Queue { event, entry },
    });
    let _ = events.send(event.clone());
    if let Some(log) = mission_log {
        log.event(now, &event, over);
    }
}

/// The function that hands a received message over with its reception
/// (see [`hand_over`]), for [`Delivery`](super::delivery::Delivery).
/// The `MACUpdate`s among them are added to `updates`, for the core to
/// apply.
fn handing_over<'a>(
    events: &'a broadcast::Sender<SharedEvent>,
    mission_log: &'a mut Option<Box<dyn MissionLog>>,
    now: i64,
    updates: &'a mut Vec<MacUpdate>,
) -> impl FnMut(ReceivedMessage, &Reception) + 'a {
    move |received, reception| {
        if received.message.descriptor().full_name() == crate::config::MAC_UPDATE_TYPE {
            match received.message.transcode_to::<MacUpdate>() {
                Ok(update) => updates.push(update),
                Err(e) => tracing::warn!("a received MACUpdate does not read: {e}"),
            }
        }
        hand_over(
            events,
            mission_log,
            now,
            (QueueEvent::Received(received), None),
            reception,
            None,
        )
    }
}
