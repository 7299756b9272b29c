//! The shore's Iridium driver (`DRIVER_IRIDIUM_SHORE`): Iridium's DirectIP
//! interface, as Goby3's shore driver uses it.
//!
//! - MO: a TCP listener (`mo_sbd_server_address`:`mo_sbd_server_port`,
//!   Goby3's default port 40001) to which the gateway delivers each MO
//!   message on a connection of its own; the payload, a Goby frame
//!   ([`super::frame`]), becomes a [`DriverEvent::Received`].
//! - MT: a transmission asked for ([`Driver::initiate_transmission`])
//!   becomes a data request for one frame of at most the device's MT size
//!   less header and CRC (259 bytes for a 9602/9603; smaller with
//!   `iridium.max_frame_size`), numbered by the driver; its destination's
//!   IMEI (`modem_id_to_imei`) gets it as a DirectIP MT message sent to
//!   the gateway (`mt_sbd_server_address`:`mt_sbd_server_port`). The
//!   result is `Sent` when the gateway's confirmation queues it, `Failed`
//!   (its frame handed back) when it refuses it, does not answer within
//!   `mt_confirmation_timeout_ms`, or cannot be reached.
//! - Acks: data for this node that asks for one is answered with an ACK
//!   sent as its own MT message at once (on reception, or with
//!   `deferred_ack` when the layer above asks); an ACK received is given
//!   the `unique_id` of the transmission whose frame it names.
//!
//! MT messages go one at a time, acks first; at most
//! [`MAX_WAITING`] transmissions wait (an older one is dropped,
//! [`DriverStatus::Skipped`]).
//!
//! Differences from Goby3: MT messages are sent without the disposition
//! flag that flushes the vehicle's MT queue unless `flush_mt_queue` is set
//! (Goby3 always sets it, dropping MT messages the vehicle has not fetched
//! yet); the RockBLOCK web service and RUDICS calls are not supported.

use std::collections::VecDeque;
use std::net::SocketAddr;
use std::time::Duration;

use protos::goby::acomms::protobuf::{
    iridium_shore_driver_config::SbdType, modem_transmission::TransmissionType, DriverConfig,
    IridiumShoreDriverConfig, ModemTransmission,
};
use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, oneshot};

use super::directip::{self, disposition, MoMessage, MtConfirmation, MtMessage};
use super::frame::{self, Direction};
use crate::check::{self, Problem};
use crate::driver::{
    Acknowledgement, Driver, DriverCommand, DriverContext, DriverError, DriverEvent, DriverStatus,
    EventSink, RawDirection, RawMessage, TransmitOutcome, TransmitResult,
};

/// Transmissions asked for that wait while an MT message is being sent.
pub const MAX_WAITING: usize = 2;

/// How long the layer above has to answer a data request.
pub const DATA_REQUEST_TIMEOUT: Duration = Duration::from_secs(1);

/// Frames sent and remembered for the acks that answer them.
const SENT_KEPT: usize = 1024;

/// The shore's Iridium driver.
#[derive(Debug)]
pub struct IridiumShoreDriver;

/// The shore section, or its defaults.
pub fn shore_config(config: &DriverConfig) -> IridiumShoreDriverConfig {
    config.iridium_shore.clone().unwrap_or_default()
}

/// Largest frame the driver offers: the device's MT limit less header and
/// CRC, or `iridium.max_frame_size` when that section is given and smaller.
pub fn max_frame_bytes(config: &DriverConfig) -> u32 {
    let shore = shore_config(config);
    let limit = frame::sbd_frame_limit(shore.device(), Direction::MobileTerminated) as u32;
    match &config.iridium {
        Some(iridium) if iridium.max_frame_size.is_some() => limit.min(iridium.max_frame_size()),
        _ => limit,
    }
}

/// Every problem of a shore configuration that [`IridiumShoreDriver::start`]
/// refuses; a port already taken only shows when it binds.
pub fn problems(config: &DriverConfig) -> Vec<Problem> {
    let mut problems = Vec::new();
    match config.modem_id {
        Some(id) if (0..=frame::MAX_MODEM_ID).contains(&id) => {}
        Some(id) => problems.push(Problem::new(
            "modem_id",
            format!("{id} does not fit the Iridium header (modem ids 0-30, as Goby3's)"),
        )),
        None => problems.push(Problem::new("modem_id", "required field is not set")),
    }
    let Some(shore) = &config.iridium_shore else {
        problems.push(Problem::new(
            "iridium_shore",
            "required for the Iridium shore driver (mt_sbd_server_address, mt_sbd_server_port, modem_id_to_imei)",
        ));
        return problems;
    };
    if shore.sbd_type() == SbdType::SbdRockblock {
        problems.push(Problem::new(
            "iridium_shore.sbd_type",
            "SBD_ROCKBLOCK is not supported (use SBD_DIRECTIP)",
        ));
    }
    if u16::try_from(shore.mo_sbd_server_port()).is_err() {
        problems.push(Problem::new(
            "iridium_shore.mo_sbd_server_port",
            format!("{} is not a TCP port", shore.mo_sbd_server_port()),
        ));
    }
    if shore
        .mo_sbd_server_address()
        .parse::<std::net::IpAddr>()
        .is_err()
    {
        problems.push(Problem::new(
            "iridium_shore.mo_sbd_server_address",
            format!("{:?} is not an IP address", shore.mo_sbd_server_address()),
        ));
    }
    if shore.mt_sbd_server_address().trim().is_empty() {
        problems.push(Problem::new(
            "iridium_shore.mt_sbd_server_address",
            "required: the gateway's DirectIP MT address",
        ));
    }
    match shore.mt_sbd_server_port {
        Some(p) if (1..=65535).contains(&p) => {}
        Some(p) => problems.push(Problem::new(
            "iridium_shore.mt_sbd_server_port",
            format!("{p} is not a TCP port"),
        )),
        None => problems.push(Problem::new(
            "iridium_shore.mt_sbd_server_port",
            "required: the gateway's DirectIP MT port",
        )),
    }
    for (i, pair) in shore.modem_id_to_imei.iter().enumerate() {
        if !directip::valid_imei(&pair.imei) {
            problems.push(Problem::new(
                format!("iridium_shore.modem_id_to_imei[{i}].imei"),
                format!("{:?} is not an IMEI (15 digits)", pair.imei),
            ));
        }
        if !(0..=frame::MAX_MODEM_ID).contains(&pair.modem_id) {
            problems.push(Problem::new(
                format!("iridium_shore.modem_id_to_imei[{i}].modem_id"),
                format!("{} does not fit the Iridium header (0-30)", pair.modem_id),
            ));
        }
        if shore.modem_id_to_imei[..i]
            .iter()
            .any(|p| p.modem_id == pair.modem_id)
        {
            problems.push(Problem::new(
                format!("iridium_shore.modem_id_to_imei[{i}].modem_id"),
                format!("modem id {} is given an IMEI twice", pair.modem_id),
            ));
        }
    }
    if shore.mt_confirmation_timeout_ms() == 0 {
        problems.push(Problem::new(
            "iridium_shore.mt_confirmation_timeout_ms",
            "must be above 0",
        ));
    }
    problems
}

impl IridiumShoreDriver {
    /// Binds the MO listener and starts the driver.
    pub async fn start(config: &DriverConfig) -> Result<Driver, DriverError> {
        check::refuse(problems(config))?;
        let shore = shore_config(config);
        let bind = SocketAddr::new(
            shore
                .mo_sbd_server_address()
                .parse()
                .map_err(|e| DriverError::Config(format!("mo_sbd_server_address: {e}")))?,
            shore.mo_sbd_server_port() as u16,
        );
        let listener = TcpListener::bind(bind)
            .await
            .map_err(|e| DriverError::io(format!("DirectIP MO listener on {bind}"), e))?;
        let shore_task = Shore {
            modem_id: config.modem_id(),
            max_frame_bytes: max_frame_bytes(config),
            deferred_ack: config.deferred_ack(),
            mt_server: format!(
                "{}:{}",
                shore.mt_sbd_server_address(),
                shore.mt_sbd_server_port()
            ),
            timeout: Duration::from_millis(u64::from(shore.mt_confirmation_timeout_ms())),
            flush: shore.flush_mt_queue(),
            shore,
            next_frame: super::driver::first_frame_number(),
            next_client_id: 1,
            sent: VecDeque::new(),
        };
        Ok(Driver::spawn("iridium_shore", move |ctx| {
            shore_task.run(listener, ctx)
        }))
    }
}

/// A frame sent, for the ack that answers it.
#[derive(Debug, Clone, Copy)]
struct SentFrame {
    dest: i32,
    frame: u32,
    unique_id: Option<u32>,
}

/// Work waiting for the MT link.
#[derive(Debug)]
enum Work {
    Ack(ModemTransmission),
    Data(ModemTransmission),
}

struct Shore {
    modem_id: i32,
    max_frame_bytes: u32,
    deferred_ack: bool,
    mt_server: String,
    timeout: Duration,
    flush: bool,
    shore: IridiumShoreDriverConfig,
    next_frame: u32,
    next_client_id: u32,
    sent: VecDeque<SentFrame>,
}

/// The outcome of an MT message sent.
type MtOutcome = Result<MtConfirmation, String>;

impl Shore {
    fn imei_of(&self, modem_id: i32) -> Option<&str> {
        self.shore
            .modem_id_to_imei
            .iter()
            .find(|p| p.modem_id == modem_id)
            .map(|p| p.imei.as_str())
    }

    fn modem_of(&self, imei: &str) -> Option<i32> {
        self.shore
            .modem_id_to_imei
            .iter()
            .find(|p| p.imei == imei)
            .map(|p| p.modem_id)
    }

    async fn run(mut self, listener: TcpListener, mut ctx: DriverContext) {
        let events = ctx.events.clone();
        let (mo_tx, mut mo_rx) = mpsc::unbounded_channel::<Result<(Vec<u8>, SocketAddr), String>>();
        let mut waiting: VecDeque<Work> = VecDeque::new();
        let mut acks: VecDeque<ModemTransmission> = VecDeque::new();
        // The MT message under way: what it carries and where its outcome comes.
        let mut under_way: Option<(Work, oneshot::Receiver<MtOutcome>)> = None;
        events.status(DriverStatus::Ready);
        loop {
            // Start the next MT message when the link is free.
            if under_way.is_none() {
                let next = acks
                    .pop_front()
                    .map(Work::Ack)
                    .or_else(|| waiting.pop_front());
                if let Some(work) = next {
                    under_way = self.begin(work, &events).await;
                    continue;
                }
            }
            tokio::select! {
                command = ctx.commands.recv() => match command {
                    Some(DriverCommand::Stop(done)) => {
                        let _ = done.send(());
                        return;
                    }
                    None => return,
                    Some(DriverCommand::Initiate(mt)) => {
                        if mt.r#type() == TransmissionType::Ack {
                            acks.push_back(mt);
                        } else {
                            waiting.push_back(Work::Data(mt));
                            if waiting.len() > MAX_WAITING {
                                waiting.pop_front();
                                events.status(DriverStatus::Skipped {
                                    reason: "an MT message is still being sent: a newer transmission takes the place of this one".into(),
                                });
                            }
                        }
                    }
                    Some(DriverCommand::Acknowledge(ack)) => {
                        if self.deferred_ack {
                            acks.extend(self.ack_of(ack));
                        }
                    }
                    Some(DriverCommand::Specific(m)) => events.status(DriverStatus::Unsupported {
                        message: prost_reflect::ReflectMessage::descriptor(&m).full_name().to_string(),
                    }),
                },
                accepted = listener.accept() => match accepted {
                    Ok((stream, peer)) => {
                        let tx = mo_tx.clone();
                        let timeout = self.timeout;
                        tokio::spawn(async move {
                            let read = tokio::time::timeout(timeout, async {
                                let mut stream = stream;
                                directip::read_message(&mut stream).await
                            })
                            .await;
                            let _ = tx.send(match read {
                                Ok(Ok(bytes)) => Ok((bytes, peer)),
                                Ok(Err(e)) => Err(format!("MO connection from {peer}: {e}")),
                                Err(_) => Err(format!("MO connection from {peer}: no whole message in {} ms", timeout.as_millis())),
                            });
                        });
                    }
                    Err(e) => {
                        events.status(DriverStatus::LinkError { reason: format!("DirectIP MO listener: {e}") });
                        tokio::time::sleep(Duration::from_millis(100)).await;
                    }
                },
                Some(mo) = mo_rx.recv() => match mo {
                    Ok((bytes, peer)) => acks.extend(self.mo_message(&bytes, peer, &events)),
                    Err(reason) => events.status(DriverStatus::LinkError { reason }),
                },
                outcome = async {
                    match &mut under_way {
                        Some((_, rx)) => rx.await.unwrap_or_else(|_| Err("the MT sender stopped".into())),
                        None => std::future::pending().await,
                    }
                } => {
                    if let Some((work, _)) = under_way.take() {
                        self.finished(work, outcome, &events);
                    }
                },
            }
        }
    }

    /// Fills (for data) and sends an MT message; `None` when nothing goes.
    async fn begin(
        &mut self,
        work: Work,
        events: &EventSink,
    ) -> Option<(Work, oneshot::Receiver<MtOutcome>)> {
        let mt = match work {
            Work::Ack(ack) => ack,
            Work::Data(asked) => {
                let max = asked
                    .max_frame_bytes
                    .map_or(self.max_frame_bytes, |m| m.min(self.max_frame_bytes));
                let template = ModemTransmission {
                    src: Some(self.modem_id),
                    dest: asked.dest.or(Some(-1)),
                    rate: Some(frame::RATE_SBD),
                    r#type: Some(TransmissionType::Data as i32),
                    max_num_frames: Some(1),
                    max_frame_bytes: Some(max),
                    frame_start: Some(self.next_frame),
                    frame: Vec::new(),
                    ..asked
                };
                let filled = events.request_data(template, DATA_REQUEST_TIMEOUT).await;
                if filled.frame.first().is_none_or(|f| f.is_empty()) {
                    events.emit(DriverEvent::TransmitResult(TransmitResult {
                        transmission: filled,
                        outcome: TransmitOutcome::NothingToSend,
                    }));
                    return None;
                }
                self.next_frame = frame::next_frame_number(self.next_frame);
                filled
            }
        };
        let is_ack = mt.r#type() == TransmissionType::Ack;
        let fail = |mt: ModemTransmission, reason: String| {
            if is_ack {
                events.status(DriverStatus::LinkError {
                    reason: format!("acknowledgement not sent: {reason}"),
                });
            } else {
                events.emit(DriverEvent::TransmitResult(TransmitResult {
                    transmission: mt,
                    outcome: TransmitOutcome::Failed(reason),
                }));
            }
        };
        let Some(imei) = self.imei_of(mt.dest()).map(str::to_string) else {
            let reason = format!(
                "no IMEI for modem id {} (modem_id_to_imei): not sent",
                mt.dest()
            );
            fail(mt, reason);
            return None;
        };
        let bytes = match frame::encode_sbd(&mt) {
            Ok(b) => b,
            Err(e) => {
                fail(mt, e.to_string());
                return None;
            }
        };
        let client_id = self.next_client_id;
        self.next_client_id = self.next_client_id.wrapping_add(1);
        let message = MtMessage {
            client_id,
            imei,
            disposition_flags: if self.flush {
                disposition::FLUSH_MT_QUEUE
            } else {
                0
            },
            payload: Some(bytes),
        };
        let encoded = message.encode();
        events.emit(DriverEvent::Raw(RawMessage {
            direction: RawDirection::Outgoing,
            bytes: encoded.clone(),
            peer: Some(self.mt_server.clone()),
        }));
        let (tx, rx) = oneshot::channel();
        let server = self.mt_server.clone();
        let timeout = self.timeout;
        tokio::spawn(async move {
            let outcome = tokio::time::timeout(timeout, send_mt(&server, &encoded)).await;
            let _ = tx.send(match outcome {
                Ok(result) => result,
                Err(_) => Err(format!(
                    "no confirmation from the gateway at {server} in {} ms",
                    timeout.as_millis()
                )),
            });
        });
        let work = if is_ack {
            Work::Ack(mt)
        } else {
            Work::Data(mt)
        };
        Some((work, rx))
    }

    fn finished(&mut self, work: Work, outcome: MtOutcome, events: &EventSink) {
        let (mt, is_ack) = match work {
            Work::Ack(mt) => (mt, true),
            Work::Data(mt) => (mt, false),
        };
        let result = match outcome {
            Ok(c) if c.accepted() => Ok(c),
            Ok(c) => Err(format!("the gateway refused the MT message: {c}")),
            Err(e) => Err(e),
        };
        match (result, is_ack) {
            (Ok(_), true) => {}
            (Ok(_), false) => {
                self.sent.push_back(SentFrame {
                    dest: mt.dest(),
                    frame: mt.frame_start(),
                    unique_id: mt.unique_id,
                });
                while self.sent.len() > SENT_KEPT {
                    self.sent.pop_front();
                }
                events.emit(DriverEvent::TransmitResult(TransmitResult {
                    transmission: mt,
                    outcome: TransmitOutcome::Sent,
                }));
            }
            (Err(reason), true) => events.status(DriverStatus::LinkError {
                reason: format!("acknowledgement not sent: {reason}"),
            }),
            (Err(reason), false) => {
                events.status(DriverStatus::LinkError {
                    reason: reason.clone(),
                });
                events.emit(DriverEvent::TransmitResult(TransmitResult {
                    transmission: mt,
                    outcome: TransmitOutcome::Failed(reason),
                }));
            }
        }
    }

    /// An MO message delivered; returns the acks to send at once.
    fn mo_message(
        &mut self,
        bytes: &[u8],
        peer: SocketAddr,
        events: &EventSink,
    ) -> Vec<ModemTransmission> {
        events.emit(DriverEvent::Raw(RawMessage {
            direction: RawDirection::Incoming,
            bytes: bytes.to_vec(),
            peer: Some(peer.to_string()),
        }));
        let unreadable = |reason: String| {
            events.status(DriverStatus::Unparseable {
                line: format!("DirectIP MO message of {} bytes from {peer}", bytes.len()),
                reason,
            })
        };
        let mo = match MoMessage::decode(bytes) {
            Ok(mo) => mo,
            Err(e) => {
                unreadable(e.to_string());
                return Vec::new();
            }
        };
        let Some(payload) = &mo.payload else {
            return Vec::new();
        };
        let mut mt = match frame::decode_sbd(payload) {
            Ok(mt) => mt,
            Err(e) => {
                unreadable(format!(
                    "payload from IMEI {} is not a Goby frame: {e}",
                    mo.header.imei
                ));
                return Vec::new();
            }
        };
        if let Some(id) = self.modem_of(&mo.header.imei) {
            if id != mt.src() {
                events.status(DriverStatus::Degraded {
                    reason: format!(
                        "IMEI {} is modem id {id} (modem_id_to_imei), its frame says {}",
                        mo.header.imei,
                        mt.src()
                    ),
                });
            }
        }
        mt.time = Some(u64::from(mo.header.time_of_session) * 1_000_000);
        if mt.r#type() == TransmissionType::Ack {
            let src = mt.src();
            mt.unique_id = mt.acked_frame.first().and_then(|&f| {
                self.sent
                    .iter()
                    .rev()
                    .find(|s| s.dest == src && i64::from(s.frame) == i64::from(f))
                    .and_then(|s| s.unique_id)
            });
        }
        let ack = (!self.deferred_ack && Acknowledgement::wanted(&mt, &[self.modem_id]))
            .then(|| Acknowledgement::all(mt.clone()));
        events.emit(DriverEvent::Received(mt));
        ack.map(|a| self.ack_of(a)).unwrap_or_default()
    }

    fn ack_of(&self, ack: Acknowledgement) -> Vec<ModemTransmission> {
        if !Acknowledgement::wanted(&ack.received, &[self.modem_id]) {
            return Vec::new();
        }
        ack.transmission()
            .map(|mut mt| {
                mt.rate = Some(frame::RATE_SBD);
                mt
            })
            .into_iter()
            .collect()
    }
}

/// Sends one DirectIP MT message and reads the confirmation.
async fn send_mt(server: &str, message: &[u8]) -> MtOutcome {
    let mut stream = TcpStream::connect(server)
        .await
        .map_err(|e| format!("cannot reach the gateway's MT listener {server}: {e}"))?;
    stream
        .write_all(message)
        .await
        .map_err(|e| format!("MT message to {server}: {e}"))?;
    let bytes = directip::read_message(&mut stream)
        .await
        .map_err(|e| format!("MT confirmation from {server}: {e}"))?;
    MtConfirmation::decode(&bytes).map_err(|e| format!("MT confirmation from {server}: {e}"))
}
