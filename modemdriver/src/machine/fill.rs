//! One data request at a time ([`Fill`]): the template asked to be
//! filled, the answer checked against it, given up after a while.

use std::time::Duration;

use protos::goby::acomms::protobuf::ModemTransmission;
use tokio::time::Instant;

use super::{Output, Outputs, RequestId};
use crate::driver::{checked_answer, DriverStatus, TransmitOutcome};

/// How long a driver waits for the layer above to fill a data request.
pub const DATA_REQUEST_TIMEOUT: Duration = Duration::from_secs(1);

/// The data request outstanding, if any.
#[derive(Debug, Default)]
pub struct Fill {
    last: u64,
    waiting: Option<Waiting>,
}

#[derive(Debug)]
struct Waiting {
    id: RequestId,
    template: ModemTransmission,
    deadline: Instant,
}

impl Fill {
    /// Asks the layer above to fill `template` ([`Output::Request`]),
    /// waiting until [`DATA_REQUEST_TIMEOUT`] after `now`.
    pub fn ask(&mut self, template: ModemTransmission, now: Instant, out: &mut Outputs) {
        self.last += 1;
        let id = RequestId(self.last);
        out.push(Output::Request {
            id,
            template: template.clone(),
        });
        self.waiting = Some(Waiting {
            id,
            template,
            deadline: now + DATA_REQUEST_TIMEOUT,
        });
    }

    /// Whether a request is outstanding.
    pub fn is_waiting(&self) -> bool {
        self.waiting.is_some()
    }

    /// Whether request `id` is the one outstanding.
    pub fn awaits(&self, id: RequestId) -> bool {
        self.waiting.as_ref().is_some_and(|w| w.id == id)
    }

    /// The answer to request `id` (`None`: not the one outstanding),
    /// checked against its template (what broke its limits is dropped and
    /// reported).
    pub fn answered(
        &mut self,
        id: RequestId,
        filled: Option<ModemTransmission>,
        out: &mut Outputs,
    ) -> Option<ModemTransmission> {
        let waiting = self.waiting.take_if(|w| w.id == id)?;
        let (mt, problems) = checked_answer(&waiting.template, filled);
        for p in problems {
            out.status(p);
        }
        Some(mt)
    }

    /// Gives the request up when its time is up at `now` (reported):
    /// its template, of which nothing is sent.
    pub fn expire(&mut self, now: Instant, out: &mut Outputs) -> Option<ModemTransmission> {
        let waiting = self.waiting.take_if(|w| w.deadline <= now)?;
        out.status(DriverStatus::DataRejected {
            reason: format!(
                "no answer to the data request within {} ms: nothing sent",
                DATA_REQUEST_TIMEOUT.as_millis()
            ),
        });
        Some(waiting.template)
    }

    /// Gives up a data transmission's request when its time is up at `now`:
    /// nothing is sent (reported, with a `NothingToSend` result).
    pub fn expire_data(&mut self, now: Instant, out: &mut Outputs) {
        if let Some(template) = self.expire(now, out) {
            out.result(template, TransmitOutcome::NothingToSend);
        }
    }

    /// When the request outstanding is given up.
    pub fn deadline(&self) -> Option<Instant> {
        self.waiting.as_ref().map(|w| w.deadline)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::driver::DriverEvent;

    #[test]
    fn an_answer_is_checked_and_a_late_one_ignored() {
        let t0 = Instant::now();
        let mut fill = Fill::default();
        let mut out = Outputs::default();
        let template = ModemTransmission {
            max_num_frames: Some(1),
            max_frame_bytes: Some(4),
            ..Default::default()
        };
        fill.ask(template.clone(), t0, &mut out);
        let Output::Request { id, .. } = out.take().remove(0) else {
            panic!("a request")
        };
        assert!(fill.awaits(id) && fill.is_waiting());
        let filled = ModemTransmission {
            frame: vec![b"12345".to_vec()],
            ..template.clone()
        };
        let mt = fill.answered(id, Some(filled), &mut out).unwrap();
        assert!(
            mt.frame.is_empty(),
            "the frame over max_frame_bytes is dropped"
        );
        assert!(matches!(
            out.take()[..],
            [Output::Event(DriverEvent::Status(
                DriverStatus::DataRejected { .. }
            ))]
        ));
        assert!(fill.answered(id, None, &mut out).is_none(), "answered once");

        fill.ask(template, t0, &mut out);
        out.take();
        fill.expire_data(t0, &mut out);
        assert!(fill.is_waiting());
        fill.expire_data(t0 + DATA_REQUEST_TIMEOUT, &mut out);
        assert!(!fill.is_waiting());
        assert_eq!(out.take().len(), 2, "the request given up, nothing sent");
    }
}
