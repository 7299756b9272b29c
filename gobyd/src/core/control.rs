//! The core's control requests: flushing a queue, restarting the
//! drivers, a driver-specific request for this node's next slot, a
//! request of the network layer.

use prost_reflect::{DynamicMessage, ReflectMessage};

use super::{Core, MAX_SPECIFIC_REQUESTS};
use crate::event::{Control, NetworkReply, NetworkRequest};

impl Core {
    /// Flushes a queue or resets the driver.
    pub(super) async fn control_request(&mut self, control: Control) {
        match control {
            Control::FlushQueue { dccl_id, reply } => {
                let flushed = match self.names.get(&dccl_id) {
                    Some(name) => self.outbox.flush(name).map_err(|e| e.to_string()),
                    None => Err(format!("no queue for DCCL id {dccl_id}")),
                };
                match &flushed {
                    Ok(n) => tracing::info!(dccl_id, "queue flushed: {n} messages"),
                    Err(e) => tracing::warn!(dccl_id, "queue flush: {e}"),
                }
                let _ = reply.send(flushed);
            }
            Control::ResetDriver { reply } => {
                let mut outcome = Ok(());
                for i in 0..self.links.len() {
                    let reset = self.reset_driver(i).await;
                    if outcome.is_ok() {
                        outcome = reset;
                    }
                }
                let _ = reply.send(outcome);
            }
            Control::Network { request, reply } => {
                let outcome = self.network_request(request);
                if let Err(e) = &outcome {
                    tracing::warn!("file transfer request: {e}");
                }
                let _ = reply.send(outcome);
            }
            Control::MacUpdate {
                update,
                from,
                reply,
            } => {
                let _ = reply.send(self.mac_update(&update, from));
            }
            Control::MacSwitch {
                mac,
                keep_alive_seconds,
                from,
                reply,
            } => {
                let _ = reply.send(self.mac_switch(mac, keep_alive_seconds, from));
            }
            Control::MacCycle { reply } => {
                let _ = reply.send(self.mac_cycle());
            }
            Control::DriverSpecific { message, reply } => {
                let outcome = self.take_specific_request(message);
                if let Err(e) = &outcome {
                    tracing::warn!("driver-specific request: {e}");
                }
                let _ = reply.send(outcome);
            }
        }
    }

    /// Carries out a client's request of the network layer (file transfer).
    pub(super) fn network_request(
        &mut self,
        request: NetworkRequest,
    ) -> Result<NetworkReply, String> {
        let now = self.clock.now();
        let Some(network) = &mut self.network else {
            return Err(
                "file transfer needs the network layer: add a network { } section to the configuration"
                    .into(),
            );
        };
        match request {
            NetworkRequest::SendFile { dest, path, name } => {
                let (event, joined) = network.send_file(dest, &path, name.as_deref(), now)?;
                self.report_transfers(vec![event.clone()]);
                Ok(NetworkReply::FileSent {
                    id: event.id,
                    joined,
                    transfer: event,
                })
            }
            NetworkRequest::GetFile { node, path } => {
                let request = network.request_file(node, &path, &mut self.outbox, now)?;
                Ok(NetworkReply::FileAsked { request, node })
            }
            NetworkRequest::Transfers => Ok(NetworkReply::Transfers(network.transfers())),
        }
    }

    /// Takes a driver-specific request to start at this node's next slot
    /// (TDMA is kept: a ping or an interrogation takes the slot in place of
    /// data), or says why not: a request the configured driver cannot carry
    /// out (see [`modemdriver::micromodem::ranging::request_problem`]), or
    /// [`MAX_SPECIFIC_REQUESTS`] waiting already.
    /// With several links, the request goes to the first link whose
    /// driver takes it.
    pub(super) fn take_specific_request(&mut self, message: DynamicMessage) -> Result<(), String> {
        let mut refusal = None;
        for i in 0..self.links.len() {
            match self.specific_request_check(i, &message) {
                Ok(()) => {
                    let link = &mut self.links[i];
                    if link.specific_requests.len() >= MAX_SPECIFIC_REQUESTS {
                        return Err(format!(
                            "{}: {MAX_SPECIFIC_REQUESTS} driver-specific requests already wait for this node's slot",
                            message.descriptor().full_name()
                        ));
                    }
                    link.specific_requests.push_back(message);
                    return Ok(());
                }
                Err(problem) => {
                    refusal.get_or_insert(problem);
                }
            }
        }
        Err(refusal.unwrap_or_else(|| "no link takes driver-specific requests".into()))
    }

    /// Whether link `i`'s driver can carry out `message` (see
    /// [`take_specific_request`](Self::take_specific_request)), or why
    /// not. A driver started by the embedding program is not checked.
    pub(super) fn specific_request_check(
        &self,
        i: usize,
        message: &DynamicMessage,
    ) -> Result<(), String> {
        match &self.links[i].config {
            Some(config) => modemdriver::built_in::specific_problem(config, message, self.modem_id),
            None => Ok(()),
        }
    }
}
