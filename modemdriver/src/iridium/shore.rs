//! The shore's Iridium driver (`DRIVER_IRIDIUM_SHORE`): Iridium's DirectIP
//! interface or the RockBLOCK web service, as Goby3's shore driver uses
//! them (`sbd_type: SBD_DIRECTIP` or `SBD_ROCKBLOCK`).
//!
//! - MO, DirectIP: a TCP listener (`mo_sbd_server_address`:
//!   `mo_sbd_server_port`, Goby3's default port 40001) to which the
//!   gateway delivers each MO message on a connection of its own.
//! - MO, RockBLOCK: an HTTP endpoint on the same address and port (path
//!   `rockblock.mo_endpoint`) taking the service's webhook posts, each
//!   with a JWT verified with the service's public key
//!   (`rockblock.jwt_public_key_file`); a post without a token, or whose
//!   token does not verify, is answered 401 or 403 and reported
//!   ([`DriverStatus::LinkError`]); a post taken is answered 200 once it is
//!   handed to the layer above ([`super::rockblock::webhook`]).
//!
//!   Either way the payload, a Goby frame ([`super::frame`]), becomes a
//!   [`DriverEvent::Received`].
//! - MT: a transmission asked for ([`Driver::initiate_transmission`])
//!   becomes a data request for one frame of at most the device's MT size
//!   less header and CRC (259 bytes for a 9602/9603; smaller with
//!   `iridium.max_frame_size`), numbered by the driver; its destination's
//!   IMEI (`modem_id_to_imei`) gets it as a DirectIP MT message sent to
//!   the gateway (`mt_sbd_server_address`:`mt_sbd_server_port`), or as a
//!   POST to RockBLOCK's MT endpoint (`rockblock.server` and
//!   `rockblock.mt_endpoint`, with the account's `username` and
//!   `password`). The result is `Sent` when the gateway's confirmation
//!   (the service's `OK,<id>`) queues it, `Failed` (its frame handed back)
//!   when it is refused, not answered within `mt_confirmation_timeout_ms`,
//!   or cannot be reached. A RockBLOCK POST that fails in a way that may
//!   pass later and that queued nothing (no connection made, HTTP 429 or
//!   503, `FAILED,99`) is made again after `rockblock.mt_retry_backoff_ms`,
//!   doubled each time, up to `rockblock.mt_attempts` POSTs. One the
//!   service may have queued (no answer in time, a broken or unknown
//!   answer, another HTTP status) is not: the same bytes twice would reach
//!   the vehicle as two messages. It fails, and the messages go again
//!   marked as possible repeats.
//! - Acks: data for this node that asks for one is answered with an ACK
//!   sent as its own MT message at once (on reception, or with
//!   `deferred_ack` when the layer above asks); an ACK received is given
//!   the `unique_id` of the transmission whose frame it names.
//!
//! MT messages go one at a time, acks first; at most
//! [`MAX_WAITING`] transmissions wait (an older one is dropped,
//! [`DriverStatus::Skipped`]).
//!
//! Differences from Goby3: MT messages are sent without the flag that
//! flushes the vehicle's MT queue unless `flush_mt_queue` is set (Goby3
//! always sets it, dropping MT messages the vehicle has not fetched yet);
//! Goby3 checks RockBLOCK's token against a key built into it and not that
//! the token's fields are the post's.
//!
//! RUDICS: with `device: DEVICE_VOICE_ENABLED_ISU` and `rudics_server_port`
//! (Goby3's condition), calls are taken on a TCP listener at
//! `mo_sbd_server_address`:`rudics_server_port` ([`super::shore_rudics`]):
//! each vehicle's call is named by its first packet; frames read on it are
//! handed up (once: a frame written again after a dropped call is acked
//! again, not delivered again); acks to a vehicle on a call, and MT data
//! for it, go on the call; while the call is up the driver asks the layer
//! above for frames for that vehicle (`rate: 1`, at most
//! `iridium.max_frame_size` bytes) at `iridium.target_bit_rate`.

use std::collections::{HashMap, VecDeque};
use std::net::SocketAddr;
use std::time::Duration;

use std::sync::Arc;

use protos::goby::acomms::protobuf::{
    iridium_shore_driver_config::{RockBlock, SbdType},
    modem_transmission::TransmissionType,
    DriverConfig, IridiumDeviceType, IridiumShoreDriverConfig, ModemTransmission,
};
use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, oneshot};
use tokio::task::JoinHandle;

use super::directip::{self, disposition, MoMessage, MtConfirmation, MtMessage};
use super::frame::{self, Direction};
use super::mo_repeats::MoRepeats;
use super::rockblock::http::{self, HttpUrl};
use super::rockblock::webhook::{self, WebhookConfig, WebhookEvent};
use super::rockblock::{JwtVerifier, MtReply, MtRequest};
use super::rudics;
use super::shore_rudics::{CallId, CallOutput, CallSettings, RudicsCalls};
use crate::driver::{
    Acknowledgement, Driver, DriverCommand, DriverContext, DriverError, DriverEvent, DriverStatus,
    EventSink, RawDirection, RawMessage, TransmitOutcome, TransmitResult,
};
use crate::kind::{About, DriverKind, FrameLimits, Named, Starting};
use crate::problem::{self, Problem};

/// Transmissions asked for that wait while an MT message is being sent.
pub const MAX_WAITING: usize = 2;

/// How long the layer above has to answer a data request.
pub const DATA_REQUEST_TIMEOUT: Duration = Duration::from_secs(1);

/// Frames sent and remembered for the acks that answer them.
const SENT_KEPT: usize = 1024;

/// The shore's Iridium driver.
#[derive(Debug)]
pub struct IridiumShoreDriver;

/// The shore section, or its defaults; with `SBD_ROCKBLOCK` and no
/// `device`, a 9602/9603 (a RockBLOCK is one).
pub fn shore_config(config: &DriverConfig) -> IridiumShoreDriverConfig {
    let mut shore = config.iridium_shore.clone().unwrap_or_default();
    if shore.sbd_type() == SbdType::SbdRockblock && shore.device.is_none() {
        shore.set_device(IridiumDeviceType::DeviceIridium96029603);
    }
    shore
}

/// The RockBLOCK section, when the service is RockBLOCK.
fn rockblock_config(shore: &IridiumShoreDriverConfig) -> Option<&RockBlock> {
    (shore.sbd_type() == SbdType::SbdRockblock)
        .then_some(shore.rockblock.as_ref())
        .flatten()
}

/// The MT endpoint's URL of a RockBLOCK section.
pub fn rockblock_mt_url(rockblock: &RockBlock) -> Result<HttpUrl, String> {
    HttpUrl::parse(rockblock.server(), rockblock.mt_endpoint())
}

/// The verifier of the webhook's JWT: `Ok(None)` when verification is off;
/// `Err` says why the key file cannot be used.
pub fn rockblock_verifier(rockblock: &RockBlock) -> Result<Option<JwtVerifier>, String> {
    if rockblock.skip_jwt_verification() {
        return Ok(None);
    }
    let Some(path) = rockblock.jwt_public_key_file.as_deref() else {
        return Err("required unless skip_jwt_verification: the PEM file of RockBLOCK's public key (published in its web service documentation)".into());
    };
    let pem = std::fs::read(path).map_err(|e| format!("{path:?}: {e}"))?;
    JwtVerifier::from_pem(&pem)
        .map(Some)
        .map_err(|e| format!("{path:?}: {e}"))
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
    let rockblock = shore.sbd_type() == SbdType::SbdRockblock;
    if rockblock {
        problems.extend(rockblock_problems(shore));
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
    if !rockblock && shore.mt_sbd_server_address().trim().is_empty() {
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
        None if rockblock => {}
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
    if let Some(port) = shore.rudics_server_port {
        let device = shore_config(config).device();
        if !(1..=65535).contains(&port) {
            problems.push(Problem::new(
                "iridium_shore.rudics_server_port",
                format!("{port} is not a TCP port"),
            ));
        } else if port == shore.mo_sbd_server_port() {
            problems.push(Problem::new(
                "iridium_shore.rudics_server_port",
                format!(
                    "{port} is also mo_sbd_server_port: the RUDICS server needs a port of its own"
                ),
            ));
        }
        if device != IridiumDeviceType::DeviceVoiceEnabledIsu {
            problems.push(Problem::new(
                "iridium_shore.rudics_server_port",
                format!("calls come from voice-enabled transceivers: set device: DEVICE_VOICE_ENABLED_ISU (not {}), or leave rudics_server_port out", device.as_str_name()),
            ));
        }
        let iridium = config.iridium.clone().unwrap_or_default();
        for (field, value, min) in [
            (
                "hangup_seconds_after_empty",
                iridium.hangup_seconds_after_empty(),
                1,
            ),
            (
                "handshake_hangup_seconds",
                iridium.handshake_hangup_seconds(),
                1,
            ),
            ("target_bit_rate", iridium.target_bit_rate(), 1),
        ] {
            if value < min {
                problems.push(Problem::new(
                    format!("iridium.{field}"),
                    format!("{value}: must be at least {min} for RUDICS calls"),
                ));
            }
        }
    }
    problems
}

/// Whether the shore takes RUDICS calls (Goby3's condition: a
/// voice-enabled device and `rudics_server_port`).
pub fn rudics_enabled(config: &DriverConfig) -> bool {
    let shore = shore_config(config);
    shore.device() == IridiumDeviceType::DeviceVoiceEnabledIsu && shore.rudics_server_port.is_some()
}

/// Largest frame sent on a call: `iridium.max_frame_size` (1500, Goby3's).
pub fn rudics_frame_bytes(config: &DriverConfig) -> u32 {
    config.iridium.clone().unwrap_or_default().max_frame_size()
}

/// The problems of the RockBLOCK settings of an `SBD_ROCKBLOCK` section.
fn rockblock_problems(shore: &IridiumShoreDriverConfig) -> Vec<Problem> {
    let mut problems = Vec::new();
    let Some(rb) = &shore.rockblock else {
        problems.push(Problem::new(
            "iridium_shore.rockblock",
            "required with sbd_type: SBD_ROCKBLOCK (username, password, jwt_public_key_file)",
        ));
        return problems;
    };
    let field = |f: &str| format!("iridium_shore.rockblock.{f}");
    if rb.username.trim().is_empty() {
        problems.push(Problem::new(
            field("username"),
            "required: the RockBLOCK account's user name",
        ));
    }
    match rockblock_mt_url(rb) {
        Ok(url) if url.tls && !http::HTTPS_SUPPORTED => problems.push(Problem::new(
            field("server"),
            format!(
                "{:?} needs HTTPS, which this build lacks (build gobyd with the feature rockblock-tls)",
                rb.server()
            ),
        )),
        Ok(_) => {}
        Err(e) => problems.push(Problem::new(field("server"), e)),
    }
    if let Err(e) = rockblock_verifier(rb) {
        problems.push(Problem::new(field("jwt_public_key_file"), e));
    }
    if !rb.mo_endpoint().starts_with('/') {
        problems.push(Problem::new(
            field("mo_endpoint"),
            format!("{:?} is not a path (it starts with /)", rb.mo_endpoint()),
        ));
    }
    if rb.mt_attempts() == 0 {
        problems.push(Problem::new(field("mt_attempts"), "must be at least 1"));
    }
    problems
}

/// What the driver is called, and where its settings are.
const ABOUT: About = About {
    named: Named::Type(protos::goby::acomms::protobuf::DriverType::DriverIridiumShore),
    short_name: "iridium_shore",
    title: "Iridium shore",
    section: Some("iridium_shore"),
    goby3_extensions: &[("goby.acomms.iridium.protobuf.shore_config", "iridium_shore")],
};

impl DriverKind for IridiumShoreDriver {
    fn about(&self) -> &'static About {
        &ABOUT
    }

    fn problems(&self, config: &DriverConfig) -> Vec<Problem> {
        problems(config)
    }

    /// The device's MT messages out, its MO messages in.
    fn frame_limits(&self, config: &DriverConfig) -> Option<FrameLimits> {
        Some(frame::frame_limits(
            shore_config(config).device(),
            Direction::MobileTerminated,
            max_frame_bytes(config) as usize,
        ))
    }

    fn start<'a>(&'a self, config: &'a DriverConfig) -> Starting<'a> {
        Box::pin(IridiumShoreDriver::start(config))
    }
}

impl IridiumShoreDriver {
    /// Binds the MO listener (DirectIP, or RockBLOCK's webhook) and starts
    /// the driver.
    pub async fn start(config: &DriverConfig) -> Result<Driver, DriverError> {
        problem::refuse(problems(config))?;
        let shore = shore_config(config);
        let bind = SocketAddr::new(
            shore
                .mo_sbd_server_address()
                .parse()
                .map_err(|e| DriverError::Config(format!("mo_sbd_server_address: {e}")))?,
            shore.mo_sbd_server_port() as u16,
        );
        let timeout = Duration::from_millis(u64::from(shore.mt_confirmation_timeout_ms()));
        let (service, what) = match rockblock_config(&shore) {
            Some(rb) => {
                let url = rockblock_mt_url(rb).map_err(|e| {
                    DriverError::Config(format!("DriverConfig.iridium_shore.rockblock.server: {e}"))
                })?;
                let verifier = rockblock_verifier(rb).map_err(|e| {
                    DriverError::Config(format!(
                        "DriverConfig.iridium_shore.rockblock.jwt_public_key_file: {e}"
                    ))
                })?;
                (
                    Service::Rockblock {
                        mt: Arc::new(RockblockMt {
                            url,
                            username: rb.username.clone(),
                            password: rb.password.clone(),
                            attempts: rb.mt_attempts(),
                            backoff: Duration::from_millis(u64::from(rb.mt_retry_backoff_ms())),
                            timeout,
                        }),
                        webhook: WebhookConfig {
                            path: rb.mo_endpoint().to_string(),
                            verifier: verifier.map(Arc::new),
                            // RockBLOCK waits 3 s for its answer.
                            answer_within: Duration::from_millis(2500),
                        },
                    },
                    "RockBLOCK webhook",
                )
            }
            None => (
                Service::DirectIp {
                    mt_server: format!(
                        "{}:{}",
                        shore.mt_sbd_server_address(),
                        shore.mt_sbd_server_port()
                    ),
                },
                "DirectIP MO listener",
            ),
        };
        let listener = TcpListener::bind(bind)
            .await
            .map_err(|e| DriverError::io(format!("{what} on {bind}"), e))?;
        let rudics = if rudics_enabled(config) {
            let at = SocketAddr::new(bind.ip(), shore.rudics_server_port() as u16);
            let l = TcpListener::bind(at)
                .await
                .map_err(|e| DriverError::io(format!("RUDICS server on {at}"), e))?;
            let iridium = config.iridium.clone().unwrap_or_default();
            Some((
                l,
                CallSettings {
                    handshake_hangup_seconds: iridium.handshake_hangup_seconds().max(1) as u32,
                    hangup_seconds_after_empty: iridium.hangup_seconds_after_empty().max(1) as u32,
                    target_bit_rate: iridium.target_bit_rate().max(1) as u32,
                },
            ))
        } else {
            None
        };
        let shore_task = Shore {
            modem_id: config.modem_id(),
            max_frame_bytes: max_frame_bytes(config),
            deferred_ack: config.deferred_ack(),
            service,
            timeout,
            flush: shore.flush_mt_queue(),
            shore,
            next_frame: super::driver::first_frame_number(&goby_time::Entropy::System),
            next_client_id: 1,
            sent: VecDeque::new(),
            rudics_frame_bytes: rudics_frame_bytes(config),
            acked: VecDeque::new(),
            mo_repeats: MoRepeats::new(),
        };
        Ok(Driver::spawn("iridium_shore", move |ctx| {
            shore_task.run(listener, rudics, ctx)
        }))
    }
}

/// How MT messages leave and MO messages come.
#[derive(Debug, Clone)]
enum Service {
    /// Iridium's DirectIP: MT messages to the gateway's listener.
    DirectIp {
        /// `HOST:PORT` of the gateway's MT listener.
        mt_server: String,
    },
    /// The RockBLOCK web service.
    Rockblock {
        /// Its MT endpoint and account.
        mt: Arc<RockblockMt>,
        /// The webhook's settings.
        webhook: WebhookConfig,
    },
}

/// RockBLOCK's MT endpoint, the account, and the retries of a POST.
#[derive(Debug)]
struct RockblockMt {
    url: HttpUrl,
    username: String,
    password: String,
    attempts: u32,
    backoff: Duration,
    timeout: Duration,
}

/// An MO message delivered, by either service.
#[derive(Debug)]
struct MoArrival {
    imei: String,
    /// The transceiver's MO message sequence number, when delivered.
    momsn: Option<u64>,
    payload: Vec<u8>,
    /// Unix seconds of the session, when known.
    time: Option<u64>,
    /// Who delivered it, for the raw log.
    peer: String,
    /// What came on the wire, for the raw log.
    raw: Vec<u8>,
    /// Told once the message is handed on (the webhook's 200).
    taken: Option<oneshot::Sender<()>>,
}

/// What the MO side tells the driver.
#[derive(Debug)]
enum MoInput {
    Arrival(MoArrival),
    Problem(DriverStatus),
}

/// Aborts a task when dropped (the MO listener's, as the driver stops).
struct AbortOnDrop(JoinHandle<()>);

impl Drop for AbortOnDrop {
    fn drop(&mut self) {
        self.0.abort();
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
    service: Service,
    timeout: Duration,
    flush: bool,
    shore: IridiumShoreDriverConfig,
    next_frame: u32,
    next_client_id: u32,
    sent: VecDeque<SentFrame>,
    rudics_frame_bytes: u32,
    /// Frames acked by the layer above (deferred acks): (src, frame).
    acked: VecDeque<(i32, u32)>,
    /// MO messages seen lately, for their repeated deliveries.
    mo_repeats: MoRepeats,
}

/// What the RUDICS server's tasks tell the driver.
#[derive(Debug)]
enum CallEvent {
    Connected(CallId, String, mpsc::UnboundedSender<Vec<u8>>),
    Bytes(CallId, Vec<u8>),
    Closed(CallId),
}

/// Accepts calls; each connection's bytes go to `tx`, and what is sent to
/// its writer goes on it (dropping the writer closes it).
async fn rudics_server(listener: TcpListener, tx: mpsc::UnboundedSender<CallEvent>) {
    let mut next: CallId = 0;
    loop {
        let Ok((stream, peer)) = listener.accept().await else {
            tokio::time::sleep(Duration::from_millis(100)).await;
            continue;
        };
        next += 1;
        let id = next;
        let _ = stream.set_nodelay(true);
        let (mut reader, mut writer) = stream.into_split();
        let (wtx, mut wrx) = mpsc::unbounded_channel::<Vec<u8>>();
        if tx
            .send(CallEvent::Connected(id, peer.to_string(), wtx))
            .is_err()
        {
            return;
        }
        let read_tx = tx.clone();
        let reading = tokio::spawn(async move {
            use tokio::io::AsyncReadExt;
            let mut buf = vec![0u8; 2048];
            loop {
                match reader.read(&mut buf).await {
                    Ok(0) | Err(_) => break,
                    Ok(n) => {
                        if read_tx
                            .send(CallEvent::Bytes(id, buf[..n].to_vec()))
                            .is_err()
                        {
                            return;
                        }
                    }
                }
            }
            let _ = read_tx.send(CallEvent::Closed(id));
        });
        tokio::spawn(async move {
            while let Some(bytes) = wrx.recv().await {
                if writer.write_all(&bytes).await.is_err() {
                    break;
                }
            }
            // Closed by the driver: the far end is hung up on.
            let _ = writer.shutdown().await;
            reading.abort();
        });
    }
}

/// The outcome of an MT message sent: `Err` says why it was not queued.
type MtOutcome = Result<(), String>;

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

    async fn run(
        mut self,
        listener: TcpListener,
        rudics: Option<(TcpListener, CallSettings)>,
        mut ctx: DriverContext,
    ) {
        let events = ctx.events.clone();
        let (call_tx, mut call_rx) = mpsc::unbounded_channel::<CallEvent>();
        let mut calls: Option<RudicsCalls> = None;
        let mut writers: HashMap<CallId, mpsc::UnboundedSender<Vec<u8>>> = HashMap::new();
        let _rudics_side = rudics.map(|(l, settings)| {
            calls = Some(RudicsCalls::new(settings));
            AbortOnDrop(tokio::spawn(rudics_server(l, call_tx)))
        });
        let (mo_tx, mut mo_rx) = mpsc::unbounded_channel::<MoInput>();
        let _mo_side = AbortOnDrop(match &self.service {
            Service::DirectIp { .. } => {
                tokio::spawn(directip_listener(listener, mo_tx, self.timeout))
            }
            Service::Rockblock { webhook, .. } => {
                tokio::spawn(rockblock_webhook(listener, webhook.clone(), mo_tx))
            }
        });
        let mut waiting: VecDeque<Work> = VecDeque::new();
        let mut acks: VecDeque<ModemTransmission> = VecDeque::new();
        // The MT message under way: what it carries and where its outcome comes.
        let mut under_way: Option<(Work, oneshot::Receiver<MtOutcome>)> = None;
        events.status(DriverStatus::Ready);
        loop {
            if let Some(c) = calls.as_mut() {
                // Acks to vehicles on a call go on it.
                let now = tokio::time::Instant::now();
                let mut kept = VecDeque::new();
                while let Some(mut ack) = acks.pop_front() {
                    if c.call_of(ack.dest()).is_none() {
                        kept.push_back(ack);
                        continue;
                    }
                    ack.rate = Some(frame::RATE_RUDICS);
                    if let Ok(bytes) = frame::encode_message(&ack) {
                        if let Some(out) = c.send(ack.dest(), rudics::encode(&bytes), now) {
                            self.call_outputs(vec![out], &mut writers, c, &mut kept, &events);
                        }
                    }
                }
                acks = kept;
                // Frames for vehicles on a call.
                for modem in c.data_wanted(now) {
                    let found = self.call_data(modem, c, &mut writers, &events).await;
                    c.answered(modem, found, tokio::time::Instant::now());
                }
            }
            // Start the next MT message when the link is free.
            if under_way.is_none() {
                let next = acks
                    .pop_front()
                    .map(Work::Ack)
                    .or_else(|| waiting.pop_front());
                if let Some(work) = next {
                    under_way = self
                        .begin(work, calls.as_mut(), &mut writers, &events)
                        .await;
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
                        } else if mt.rate == Some(frame::RATE_RUDICS) && calls.is_some() {
                            // As Goby3's: data at the RUDICS rate goes on
                            // calls only, which ask for it themselves.
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
                            self.acked.push_back((ack.received.src(), ack.received.frame_start()));
                            while self.acked.len() > SENT_KEPT {
                                self.acked.pop_front();
                            }
                            acks.extend(self.ack_of(ack));
                        }
                    }
                    Some(DriverCommand::Specific(m)) => events.status(DriverStatus::Unsupported {
                        message: prost_reflect::ReflectMessage::descriptor(&m).full_name().to_string(),
                    }),
                },
                Some(mo) = mo_rx.recv() => match mo {
                    MoInput::Arrival(arrival) => acks.extend(self.mo_message(arrival, &events)),
                    MoInput::Problem(status) => events.status(status),
                },
                Some(event) = call_rx.recv() => {
                    if let Some(c) = calls.as_mut() {
                        self.call_event(event, c, &mut writers, &mut acks, &events);
                    }
                },
                () = crate::time::sleep_until_opt(calls.as_ref().and_then(RudicsCalls::next_deadline)) => {
                    if let Some(c) = calls.as_mut() {
                        let outs = c.tick(tokio::time::Instant::now());
                        self.call_outputs(outs, &mut writers, c, &mut acks, &events);
                    }
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

    /// What a RUDICS call brought: a call connected, bytes, a call ended.
    fn call_event(
        &mut self,
        event: CallEvent,
        c: &mut RudicsCalls,
        writers: &mut HashMap<CallId, mpsc::UnboundedSender<Vec<u8>>>,
        acks: &mut VecDeque<ModemTransmission>,
        events: &EventSink,
    ) {
        let now = tokio::time::Instant::now();
        let outs = match event {
            CallEvent::Connected(id, peer, writer) => {
                tracing::info!("RUDICS call {id} from {peer}");
                writers.insert(id, writer);
                c.connected(id, peer, now);
                Vec::new()
            }
            CallEvent::Bytes(id, bytes) => {
                events.emit(DriverEvent::Raw(RawMessage {
                    direction: RawDirection::Incoming,
                    bytes: bytes.clone(),
                    peer: Some(format!("RUDICS call {id}")),
                }));
                c.bytes(id, &bytes, now)
            }
            CallEvent::Closed(id) => {
                tracing::info!("RUDICS call {id} ended");
                writers.remove(&id);
                c.closed(id);
                Vec::new()
            }
        };
        self.call_outputs(outs, writers, c, acks, events);
    }

    /// Does what the calls ask.
    fn call_outputs(
        &mut self,
        outs: Vec<CallOutput>,
        writers: &mut HashMap<CallId, mpsc::UnboundedSender<Vec<u8>>>,
        calls: &mut RudicsCalls,
        acks: &mut VecDeque<ModemTransmission>,
        events: &EventSink,
    ) {
        for out in outs {
            match out {
                CallOutput::Write(id, bytes) => {
                    events.emit(DriverEvent::Raw(RawMessage {
                        direction: RawDirection::Outgoing,
                        bytes: bytes.clone(),
                        peer: Some(format!("RUDICS call {id}")),
                    }));
                    if let Some(w) = writers.get(&id) {
                        let _ = w.send(bytes);
                    }
                }
                CallOutput::Close(id) => {
                    // Dropping the writer closes the connection once what
                    // was written has gone.
                    writers.remove(&id);
                    calls.closed(id);
                }
                CallOutput::Received(mt) => acks.extend(self.deliver(mt, events)),
                CallOutput::Duplicate(mt) => {
                    events.status(DriverStatus::Skipped {
                        reason: format!(
                            "frame {} from modem {} taken already on an earlier call: not delivered again",
                            mt.frame_start(),
                            mt.src()
                        ),
                    });
                    let acked =
                        !self.deferred_ack || self.acked.contains(&(mt.src(), mt.frame_start()));
                    if acked && Acknowledgement::wanted(&mt, &[self.modem_id]) {
                        acks.extend(self.ack_of(Acknowledgement::all(mt)));
                    }
                }
                CallOutput::Status(status) => events.status(status),
            }
        }
    }

    /// Asks the layer above for a frame for vehicle `modem` on its call and
    /// writes it; whether there was one.
    async fn call_data(
        &mut self,
        modem: i32,
        calls: &mut RudicsCalls,
        writers: &mut HashMap<CallId, mpsc::UnboundedSender<Vec<u8>>>,
        events: &EventSink,
    ) -> bool {
        let template = ModemTransmission {
            src: Some(self.modem_id),
            dest: Some(modem),
            rate: Some(frame::RATE_RUDICS),
            r#type: Some(TransmissionType::Data as i32),
            max_num_frames: Some(1),
            max_frame_bytes: Some(self.rudics_frame_bytes),
            frame_start: Some(self.next_frame),
            ..Default::default()
        };
        let filled = events.request_data(template, DATA_REQUEST_TIMEOUT).await;
        if filled.frame.first().is_none_or(|f| f.is_empty()) {
            return false;
        }
        self.next_frame = frame::next_frame_number(self.next_frame);
        let bytes = match frame::encode_message(&filled) {
            Ok(b) => b,
            Err(e) => {
                events.emit(DriverEvent::TransmitResult(TransmitResult {
                    transmission: filled,
                    outcome: TransmitOutcome::Failed(e.to_string()),
                }));
                return false;
            }
        };
        match calls.send(modem, rudics::encode(&bytes), tokio::time::Instant::now()) {
            Some(out) => {
                let mut none = VecDeque::new();
                self.call_outputs(vec![out], writers, calls, &mut none, events);
                self.finished(Work::Data(filled), Ok(()), events);
            }
            None => events.emit(DriverEvent::TransmitResult(TransmitResult {
                transmission: filled,
                outcome: TransmitOutcome::Failed(format!("the call of modem {modem} ended")),
            })),
        }
        true
    }

    /// Fills (for data) and sends an MT message; `None` when nothing goes.
    /// A frame for a vehicle on a call goes on the call (as Goby3's).
    async fn begin(
        &mut self,
        work: Work,
        calls: Option<&mut RudicsCalls>,
        writers: &mut HashMap<CallId, mpsc::UnboundedSender<Vec<u8>>>,
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
        if let Some(c) = calls {
            if c.call_of(mt.dest()).is_some() {
                let mut on_call = mt.clone();
                on_call.rate = Some(frame::RATE_RUDICS);
                if let Ok(bytes) = frame::encode_message(&on_call) {
                    let now = tokio::time::Instant::now();
                    if let Some(out) = c.send(mt.dest(), rudics::encode(&bytes), now) {
                        let mut none = VecDeque::new();
                        self.call_outputs(vec![out], writers, c, &mut none, events);
                        if !is_ack {
                            self.finished(Work::Data(on_call), Ok(()), events);
                        }
                        return None;
                    }
                }
            }
        }
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
        let (tx, rx) = oneshot::channel();
        match &self.service {
            Service::DirectIp { mt_server } => {
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
                    peer: Some(mt_server.clone()),
                }));
                let server = mt_server.clone();
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
            }
            Service::Rockblock { mt: service, .. } => {
                // The SBD message itself, not the form (which holds the
                // account's password), goes to the raw log.
                events.emit(DriverEvent::Raw(RawMessage {
                    direction: RawDirection::Outgoing,
                    bytes: bytes.clone(),
                    peer: Some(format!("{} IMEI {imei}", service.url)),
                }));
                let request = MtRequest {
                    imei,
                    username: service.username.clone(),
                    password: service.password.clone(),
                    data: bytes,
                    flush: self.flush,
                };
                let service = service.clone();
                let events = events.clone();
                tokio::spawn(async move {
                    let _ = tx.send(post_mt(&service, &request, &events).await);
                });
            }
        }
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
        match (outcome, is_ack) {
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
    fn mo_message(&mut self, arrival: MoArrival, events: &EventSink) -> Vec<ModemTransmission> {
        let MoArrival {
            imei,
            momsn,
            payload,
            time,
            peer,
            raw,
            taken,
        } = arrival;
        events.emit(DriverEvent::Raw(RawMessage {
            direction: RawDirection::Incoming,
            bytes: raw,
            peer: Some(peer.clone()),
        }));
        // Handed on, or reported as not a Goby frame: either way the
        // service is answered, as delivering it again would change nothing.
        if let Some(taken) = taken {
            let _ = taken.send(());
        }
        if payload.is_empty() {
            return Vec::new();
        }
        if !self.mo_repeats.first(&imei, momsn, &payload) {
            tracing::info!(
                "MO message {} of IMEI {imei} delivered again (its session was reported failed after the gateway took it): taken once",
                momsn.unwrap_or_default()
            );
            return Vec::new();
        }
        let mut mt = match frame::decode_sbd(&payload) {
            Ok(mt) => mt,
            Err(e) => {
                events.status(DriverStatus::Unparseable {
                    line: format!("MO message of {} bytes from {peer}", payload.len()),
                    reason: format!("payload from IMEI {imei} is not a Goby frame: {e}"),
                });
                return Vec::new();
            }
        };
        if let Some(id) = self.modem_of(&imei) {
            if id != mt.src() {
                events.status(DriverStatus::Degraded {
                    reason: format!(
                        "IMEI {imei} is modem id {id} (modem_id_to_imei), its frame says {}",
                        mt.src()
                    ),
                });
            }
        }
        mt.time = time.map(|t| t * 1_000_000);
        // The gateway posts it again when its delivery was not answered
        // (the shore killed before its answer went): after a restart the
        // repeat is not known here, and the receiver's record tells it.
        mt.may_repeat = Some(true);
        self.deliver(mt, events)
    }

    /// A transmission read (MO message or call): an ack is credited, data
    /// handed up; returns the acks to send at once.
    fn deliver(&mut self, mut mt: ModemTransmission, events: &EventSink) -> Vec<ModemTransmission> {
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

/// The DirectIP MO listener: each connection's message, read within
/// `timeout`, goes to `tx`. Never returns (aborted with the driver).
async fn directip_listener(
    listener: TcpListener,
    tx: mpsc::UnboundedSender<MoInput>,
    timeout: Duration,
) {
    loop {
        let (stream, peer) = match listener.accept().await {
            Ok(accepted) => accepted,
            Err(e) => {
                let _ = tx.send(MoInput::Problem(DriverStatus::LinkError {
                    reason: format!("DirectIP MO listener: {e}"),
                }));
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        let tx = tx.clone();
        tokio::spawn(async move {
            let read = tokio::time::timeout(timeout, async {
                let mut stream = stream;
                directip::read_message(&mut stream).await
            })
            .await;
            let bytes = match read {
                Ok(Ok(bytes)) => bytes,
                Ok(Err(e)) => {
                    let _ = tx.send(MoInput::Problem(DriverStatus::LinkError {
                        reason: format!("MO connection from {peer}: {e}"),
                    }));
                    return;
                }
                Err(_) => {
                    let _ = tx.send(MoInput::Problem(DriverStatus::LinkError {
                        reason: format!(
                            "MO connection from {peer}: no whole message in {} ms",
                            timeout.as_millis()
                        ),
                    }));
                    return;
                }
            };
            let input = match MoMessage::decode(&bytes) {
                Ok(mo) => MoInput::Arrival(MoArrival {
                    imei: mo.header.imei.clone(),
                    momsn: Some(u64::from(mo.header.momsn)),
                    payload: mo.payload.unwrap_or_default(),
                    time: Some(u64::from(mo.header.time_of_session)),
                    peer: peer.to_string(),
                    raw: bytes,
                    taken: None,
                }),
                Err(e) => MoInput::Problem(DriverStatus::Unparseable {
                    line: format!("DirectIP MO message of {} bytes from {peer}", bytes.len()),
                    reason: e.to_string(),
                }),
            };
            let _ = tx.send(input);
        });
    }
}

/// RockBLOCK's webhook: posts taken go to `tx` as arrivals, refusals as
/// problems (and a warning in the log). Returns only if serving fails.
async fn rockblock_webhook(
    listener: TcpListener,
    config: WebhookConfig,
    tx: mpsc::UnboundedSender<MoInput>,
) {
    let (events_tx, mut events_rx) = mpsc::unbounded_channel();
    let addr = listener.local_addr().ok();
    let server = tokio::spawn(webhook::serve(listener, config, events_tx));
    let _server = AbortOnDrop(tokio::spawn(async move {
        if let Ok(Err(e)) = server.await {
            tracing::error!("RockBLOCK webhook on {addr:?}: {e}");
        }
    }));
    while let Some(event) = events_rx.recv().await {
        let input = match event {
            WebhookEvent::Arrival {
                post,
                body,
                peer,
                taken,
            } => MoInput::Arrival(MoArrival {
                time: post
                    .transmit_time
                    .as_deref()
                    .and_then(super::rockblock::transmit_time_seconds),
                imei: post.imei,
                momsn: post.momsn,
                payload: post.data,
                peer: format!("RockBLOCK webhook from {peer}"),
                raw: body,
                taken: Some(taken),
            }),
            WebhookEvent::Refused {
                peer,
                status,
                reason,
            } => {
                tracing::warn!("RockBLOCK webhook: post from {peer} refused ({status}): {reason}");
                MoInput::Problem(DriverStatus::LinkError {
                    reason: format!(
                        "RockBLOCK webhook: post from {peer} refused ({status}): {reason}"
                    ),
                })
            }
        };
        if tx.send(input).is_err() {
            return;
        }
    }
}

/// POSTs one MT message to RockBLOCK, again after a failure that may pass
/// and left nothing queued (up to `service.attempts` POSTs, reported as
/// [`DriverStatus::Retrying`]): no connection made, RockBLOCK's own
/// `FAILED` answer with a code that may pass, or HTTP 429 or 503 (the
/// request not served). A POST that may have been queued (no answer in
/// time, a broken or unknown answer, another HTTP status) is not made
/// again with the same bytes, which the vehicle would take for a new
/// message: it fails, and its messages go again marked as possible repeats.
async fn post_mt(service: &RockblockMt, request: &MtRequest, events: &EventSink) -> MtOutcome {
    let form = request.to_form().into_bytes();
    let mut wait = service.backoff;
    let mut attempt = 1;
    loop {
        let (reason, may_pass) = match http::post(
            &service.url,
            "application/x-www-form-urlencoded",
            form.clone(),
            service.timeout,
        )
        .await
        {
            Err(e) => (e.message, e.unsent),
            Ok(reply) if reply.status != 200 => (
                format!(
                    "RockBLOCK MT endpoint {} answered HTTP {}",
                    service.url, reply.status
                ),
                matches!(reply.status, 429 | 503),
            ),
            Ok(reply) => match MtReply::parse(&String::from_utf8_lossy(&reply.body)) {
                Ok(MtReply::Queued { .. }) => return Ok(()),
                Ok(failed @ MtReply::Failed { code, .. }) => (
                    format!("RockBLOCK {failed} for IMEI {}", request.imei),
                    code.may_pass_later(),
                ),
                Err(e) => (
                    format!(
                        "RockBLOCK MT endpoint {}: unexpected answer {e}",
                        service.url
                    ),
                    false,
                ),
            },
        };
        if !may_pass || attempt >= service.attempts {
            let tried = if attempt > 1 {
                format!(" ({attempt} POSTs)")
            } else {
                String::new()
            };
            return Err(format!("{reason}{tried}"));
        }
        attempt += 1;
        events.status(DriverStatus::Retrying {
            reason: format!("{reason}; POST again in {} ms", wait.as_millis()),
            attempt,
        });
        tokio::time::sleep(wait).await;
        wait = wait.saturating_mul(2);
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
    let c = MtConfirmation::decode(&bytes)
        .map_err(|e| format!("MT confirmation from {server}: {e}"))?;
    if c.accepted() {
        Ok(())
    } else {
        Err(format!("the gateway refused the MT message: {c}"))
    }
}
