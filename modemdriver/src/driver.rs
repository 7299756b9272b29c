//! The driver interface: a running driver task, the commands it takes and the
//! events it reports.
//!
//! A driver is started by its own constructor (e.g.
//! [`UdpDriver::start`](crate::udp::UdpDriver::start)), which spawns a tokio
//! task and returns a [`Driver`]. The layer above then
//! - asks for transmissions with [`Driver::initiate_transmission`] (or
//!   [`DriverHandle::initiate_transmission`] from another task),
//! - reads [`DriverEvent`]s with [`Driver::next_event`], answering each
//!   [`DriverEvent::DataRequest`] with the frames to send,
//! - acknowledges received data once it has recorded it, with
//!   [`Driver::acknowledge`], when the driver was started with
//!   `DriverConfig.deferred_ack` (drivers that ack in software only),
//! - stops the driver with [`Driver::stop`].

use std::time::Duration;

use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::{modem_transmission::TransmissionType, ModemTransmission};
use std::sync::Arc;
use tokio::sync::{mpsc, oneshot};
use tokio::task::JoinHandle;

/// Why a driver could not start or take a command.
#[derive(Debug, thiserror::Error)]
pub enum DriverError {
    /// The configuration is missing something or holds a bad value.
    #[error("bad driver configuration: {0}")]
    Config(String),
    /// An I/O operation failed (e.g. binding a socket, opening a port).
    #[error("{context}: {source}")]
    Io {
        /// What was being done.
        context: String,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The driver task has ended.
    #[error("the driver has stopped")]
    Stopped,
}

impl DriverError {
    /// Builds a [`DriverError::Io`].
    pub fn io(context: impl Into<String>, source: std::io::Error) -> Self {
        DriverError::Io {
            context: context.into(),
            source,
        }
    }
}

/// A command to a driver task.
#[derive(Debug)]
pub enum DriverCommand {
    /// Start a transmission (data, or an acknowledgement ...).
    Initiate(ModemTransmission),
    /// A driver-specific request (e.g. a Micro-Modem two-way ping); drivers
    /// that do not know the message report [`DriverStatus::Unsupported`].
    Specific(DynamicMessage),
    /// Acknowledge frames of a received transmission, now that the layer
    /// above has recorded their messages. Acted on by drivers that send
    /// acknowledgements in software and were started with
    /// `DriverConfig.deferred_ack`; ignored otherwise (a driver acking on
    /// reception, a modem acking in hardware).
    Acknowledge(Acknowledgement),
    /// Stop; the sender is told when the task is done.
    Stop(oneshot::Sender<()>),
}

/// Frames of a received transmission to acknowledge
/// ([`DriverCommand::Acknowledge`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Acknowledgement {
    /// The transmission as the driver reported it in
    /// [`DriverEvent::Received`] (its `src`, `dest`, `rate`, `frame_start`
    /// and `unique_id` name what the acknowledgement answers).
    pub received: ModemTransmission,
    /// Indices into `received.frame` of the frames to acknowledge.
    pub frames: Vec<usize>,
}

impl Acknowledgement {
    /// Acknowledges every frame of `received`.
    pub fn all(received: ModemTransmission) -> Self {
        let frames = (0..received.frame.len()).collect();
        Acknowledgement { received, frames }
    }

    /// Whether a driver acknowledging in software answers `received` at
    /// all: data with `ack_requested`, frames in it, addressed to one of
    /// `ack_ids` (this node and any it acknowledges for).
    pub fn wanted(received: &ModemTransmission, ack_ids: &[i32]) -> bool {
        received.r#type() == TransmissionType::Data
            && received.ack_requested()
            && ack_ids.contains(&received.dest())
            && !received.frame.is_empty()
    }

    /// The `ACK` transmission answering the frames: from the data's
    /// destination to its source, at its rate, listing the frame numbers
    /// (`frame_start` + index, indices past the last frame left out) and
    /// echoing its `unique_id` so that the sender credits the transmission
    /// it answers. `None` when no frame is left to acknowledge.
    pub fn transmission(&self) -> Option<ModemTransmission> {
        let mt = &self.received;
        let mut acked: Vec<i32> = self
            .frames
            .iter()
            .filter(|&&i| i < mt.frame.len())
            .map(|&i| mt.frame_start() as i32 + i as i32)
            .collect();
        acked.sort_unstable();
        acked.dedup();
        if acked.is_empty() {
            return None;
        }
        Some(ModemTransmission {
            src: Some(mt.dest()),
            dest: Some(mt.src()),
            rate: mt.rate,
            r#type: Some(TransmissionType::Ack as i32),
            acked_frame: acked,
            unique_id: mt.unique_id,
            ..Default::default()
        })
    }
}

/// What a driver reports.
#[derive(Debug)]
pub enum DriverEvent {
    /// A transmission heard on the link (data or acknowledgement), whoever it
    /// is addressed to.
    Received(ModemTransmission),
    /// The outcome of a transmission this node initiated.
    TransmitResult(TransmitResult),
    /// The driver is about to send and asks for the frames.
    DataRequest(DataRequest),
    /// A raw line or datagram, as read from or written to the device.
    Raw(RawMessage),
    /// A fault met, or a recovery from one.
    Status(DriverStatus),
    /// A driver-specific result (e.g. a Micro-Modem ranging reply).
    Specific(SpecificReport),
}

/// A request to fill the frames of a transmission at the moment of sending.
///
/// Answer with [`DataRequest::respond`]. Dropping the request (or not
/// answering within the driver's data request timeout) sends no data.
#[derive(Debug)]
pub struct DataRequest {
    template: ModemTransmission,
    reply: oneshot::Sender<ModemTransmission>,
}

impl DataRequest {
    /// The transmission to fill: `src`, `dest`, `rate`, `max_num_frames`,
    /// `max_frame_bytes` and `frame_start` are set by the driver.
    pub fn template(&self) -> &ModemTransmission {
        &self.template
    }

    /// Answers with the filled transmission (frames added to the template;
    /// `dest` may be set when the template's is -1).
    pub fn respond(self, filled: ModemTransmission) {
        // The driver may have given up waiting: nothing to do then.
        let _ = self.reply.send(filled);
    }
}

/// The outcome of an initiated transmission.
#[derive(Debug, Clone, PartialEq)]
pub struct TransmitResult {
    /// The transmission as sent (frames included) or as attempted.
    pub transmission: ModemTransmission,
    /// What happened.
    pub outcome: TransmitOutcome,
}

/// What happened to an initiated transmission.
#[derive(Debug, Clone, PartialEq)]
pub enum TransmitOutcome {
    /// It went out on the link.
    Sent,
    /// The layer above gave no data to send: nothing went out.
    NothingToSend,
    /// It could not be sent; the frames (if any were filled) are in the
    /// result's transmission so that the caller can queue them again.
    Failed(String),
}

/// Direction of a raw message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RawDirection {
    /// Read from the device.
    Incoming,
    /// Written to the device.
    Outgoing,
}

/// A raw line (delimiter removed) or datagram, for logging and debugging.
#[derive(Debug, Clone, PartialEq)]
pub struct RawMessage {
    /// Read or written.
    pub direction: RawDirection,
    /// The bytes.
    pub bytes: Vec<u8>,
    /// The peer (e.g. a socket address), when the device has several.
    pub peer: Option<String>,
}

/// A fault met by a driver, or a recovery from one.
#[derive(Debug, Clone, PartialEq)]
pub enum DriverStatus {
    /// The driver configured its device and is ready.
    Ready,
    /// A line whose checksum does not match; it was ignored.
    BadChecksum {
        /// The line as read.
        line: String,
    },
    /// A line or datagram that cannot be understood; it was ignored.
    Unparseable {
        /// The line or datagram as read (lossy UTF-8).
        line: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A command got no answer in time.
    ResponseTimeout {
        /// The command.
        command: String,
        /// Attempts made so far.
        attempt: u32,
    },
    /// A transmission is attempted again after a failure.
    Retrying {
        /// Why.
        reason: String,
        /// The attempt about to be made (2 for the first retry).
        attempt: u32,
    },
    /// The modem restarted; the driver configures it again.
    ModemReset,
    /// Nothing was heard from the modem for this long.
    ModemSilent {
        /// Seconds of silence.
        seconds: f64,
    },
    /// The modem reported an error ($CAERR, $CAMSG).
    ModemError {
        /// The modem's words.
        message: String,
    },
    /// The device went away.
    Disconnected {
        /// Why.
        reason: String,
    },
    /// The device is back.
    Reconnected,
    /// The answer to a data request broke the template's limits; the
    /// offending frames were dropped.
    DataRejected {
        /// What was wrong.
        reason: String,
    },
    /// Sending or receiving on the device failed (the driver goes on).
    LinkError {
        /// What failed.
        reason: String,
    },
    /// A transmission was not made: its slot had passed (e.g. it waited
    /// while the modem was unreachable), or newer ones replaced it.
    Skipped {
        /// Why.
        reason: String,
    },
    /// The driver goes on with a weaker guarantee than it should (e.g. a
    /// Micro-Modem application-ack frame number used again while an ack of
    /// its earlier use may still come).
    Degraded {
        /// What is weaker, and why.
        reason: String,
    },
    /// The link's signal changed (e.g. an Iridium transceiver's `+CIEV`
    /// indicators): what is known of it now.
    Signal {
        /// Signal strength, 0–5 bars, when reported.
        bars: Option<u8>,
        /// Whether the network is available, when reported.
        service: Option<bool>,
    },
    /// The driver does not know a driver-specific request.
    Unsupported {
        /// The request's message type.
        message: String,
    },
}

impl DriverStatus {
    /// The status's name in `snake_case` (`"ready"`, `"bad_checksum"`,
    /// `"skipped"`, ...), as the JSON interface and MQTT carry it.
    pub fn kind(&self) -> &'static str {
        match self {
            DriverStatus::Ready => "ready",
            DriverStatus::BadChecksum { .. } => "bad_checksum",
            DriverStatus::Unparseable { .. } => "unparseable",
            DriverStatus::ResponseTimeout { .. } => "response_timeout",
            DriverStatus::Retrying { .. } => "retrying",
            DriverStatus::ModemReset => "modem_reset",
            DriverStatus::ModemSilent { .. } => "modem_silent",
            DriverStatus::ModemError { .. } => "modem_error",
            DriverStatus::Disconnected { .. } => "disconnected",
            DriverStatus::Reconnected => "reconnected",
            DriverStatus::DataRejected { .. } => "data_rejected",
            DriverStatus::LinkError { .. } => "link_error",
            DriverStatus::Skipped { .. } => "skipped",
            DriverStatus::Degraded { .. } => "degraded",
            DriverStatus::Signal { .. } => "signal",
            DriverStatus::Unsupported { .. } => "unsupported",
        }
    }
}

/// In words, for logs and operators: e.g. `transmission skipped: its slot
/// had passed`, `no answer to $CCCFG,SRC,1 (attempt 2)`.
impl std::fmt::Display for DriverStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DriverStatus::Ready => write!(f, "ready"),
            DriverStatus::BadChecksum { line } => write!(f, "bad checksum, line ignored: {line}"),
            DriverStatus::Unparseable { line, reason } => {
                write!(f, "not understood, ignored ({reason}): {line}")
            }
            DriverStatus::ResponseTimeout { command, attempt } => {
                write!(f, "no answer to {command} (attempt {attempt})")
            }
            DriverStatus::Retrying { reason, attempt } => {
                write!(f, "trying again (attempt {attempt}): {reason}")
            }
            DriverStatus::ModemReset => write!(f, "the modem restarted; configuring it again"),
            DriverStatus::ModemSilent { seconds } => {
                write!(f, "nothing heard from the modem for {seconds:.1} s")
            }
            DriverStatus::ModemError { message } => write!(f, "modem error: {message}"),
            DriverStatus::Disconnected { reason } => write!(f, "disconnected: {reason}"),
            DriverStatus::Reconnected => write!(f, "reconnected"),
            DriverStatus::DataRejected { reason } => write!(f, "data rejected: {reason}"),
            DriverStatus::LinkError { reason } => write!(f, "link error: {reason}"),
            DriverStatus::Skipped { reason } => write!(f, "transmission skipped: {reason}"),
            DriverStatus::Degraded { reason } => write!(f, "degraded: {reason}"),
            DriverStatus::Signal { bars, service } => {
                write!(f, "signal: ")?;
                match bars {
                    Some(b) => write!(f, "{b} bars")?,
                    None => write!(f, "strength unknown")?,
                }
                match service {
                    Some(true) => write!(f, ", network service available"),
                    Some(false) => write!(f, ", no network service"),
                    None => Ok(()),
                }
            }
            DriverStatus::Unsupported { message } => {
                write!(f, "driver-specific request not supported: {message}")
            }
        }
    }
}

/// A driver-specific result: a protobuf message whose type the driver
/// documents (e.g. `goby.acomms.protobuf.MicroModemSpecific`).
#[derive(Debug, Clone, PartialEq)]
pub struct SpecificReport {
    /// The result.
    pub message: DynamicMessage,
}

impl SpecificReport {
    /// Wraps a generated message.
    pub fn new(message: &impl ReflectMessage) -> Self {
        SpecificReport {
            message: message.transcode_to_dynamic(),
        }
    }

    /// The result as a generated message type, when it is of that type.
    pub fn to<T: ReflectMessage + Default>(&self) -> Option<T> {
        if self.message.descriptor() != T::default().descriptor() {
            return None;
        }
        self.message.transcode_to::<T>().ok()
    }
}

/// Where a driver task sends its events; also asks the layer above for data.
#[derive(Debug, Clone)]
pub struct EventSink {
    events: mpsc::UnboundedSender<DriverEvent>,
}

impl EventSink {
    /// Sends an event (dropped silently if nobody listens any more).
    pub fn emit(&self, event: DriverEvent) {
        let _ = self.events.send(event);
    }

    /// Reports a status.
    pub fn status(&self, status: DriverStatus) {
        self.emit(DriverEvent::Status(status));
    }

    /// Asks the layer above to fill `template` and waits up to `timeout`.
    ///
    /// The answer is checked against the template: at most `max_num_frames`
    /// frames, each at most `max_frame_bytes` long (longer ones are dropped
    /// and reported); `src`, `rate` and `frame_start` are kept from the
    /// template. Bytes already in the template's frames (e.g. a driver's
    /// own header) are the answer's to keep: the answer's frames replace
    /// them. With no answer, the template comes back as it was.
    pub async fn request_data(
        &self,
        template: ModemTransmission,
        timeout: Duration,
    ) -> ModemTransmission {
        let (request, answer) = DataRequest::new(template.clone());
        self.emit(DriverEvent::DataRequest(request));
        let filled = tokio::time::timeout(timeout, answer)
            .await
            .ok()
            .and_then(Result::ok);
        let (out, problems) = checked_answer(&template, filled);
        for status in problems {
            self.status(status);
        }
        out
    }
}

impl DataRequest {
    /// A request to fill `template`, and where its answer comes.
    pub(crate) fn new(template: ModemTransmission) -> (Self, oneshot::Receiver<ModemTransmission>) {
        let (reply, answer) = oneshot::channel();
        (DataRequest { template, reply }, answer)
    }
}

/// The answer to a data request for `template` (`None`: no answer),
/// checked against it: at most `max_num_frames` frames, each at most
/// `max_frame_bytes` long (longer ones are dropped, and reported in the
/// statuses returned); `src`, `rate` and `frame_start` are kept from the
/// template, `dest` taken from the answer when the template's is -1,
/// trailing empty frames dropped, each kept frame's `frame_identity` kept
/// beside it (a dropped frame's dropped). With no answer, the template as
/// it was.
pub(crate) fn checked_answer(
    template: &ModemTransmission,
    filled: Option<ModemTransmission>,
) -> (ModemTransmission, Vec<DriverStatus>) {
    let Some(filled) = filled else {
        return (template.clone(), Vec::new());
    };
    let mut problems = Vec::new();
    let mut out = template.clone();
    out.frame.clear();
    out.frame_identity.clear();
    let mut identities = filled.frame_identity.into_iter();
    if template.dest() == -1 {
        out.dest = filled.dest;
    }
    out.ack_requested = filled.ack_requested.or(template.ack_requested);
    let max_frames = template.max_num_frames() as usize;
    for (i, frame) in filled.frame.into_iter().enumerate() {
        let identity = identities.next().unwrap_or_default();
        if i >= max_frames {
            problems.push(DriverStatus::DataRejected {
                reason: format!(
                    "data request answer holds more than max_num_frames = {max_frames} frames; frames from {i} on dropped"
                ),
            });
            break;
        }
        match template.max_frame_bytes {
            Some(max) if frame.len() > max as usize => {
                problems.push(DriverStatus::DataRejected {
                    reason: format!(
                        "frame {i} of {} bytes exceeds max_frame_bytes = {max}; dropped",
                        frame.len()
                    ),
                });
                out.frame.push(Vec::new());
                out.frame_identity.push(Vec::new());
            }
            _ => {
                out.frame.push(frame);
                out.frame_identity.push(identity);
            }
        }
    }
    // Trailing empty frames carry nothing.
    while out.frame.last().is_some_and(|f| f.is_empty()) {
        out.frame.pop();
    }
    out.frame_identity.truncate(out.frame.len());
    while out.frame_identity.last().is_some_and(|f| f.is_empty()) {
        out.frame_identity.pop();
    }
    (out, problems)
}

/// What a driver task is given: its commands, its event sink and its clock.
pub struct DriverContext {
    /// Commands from the [`Driver`].
    pub commands: mpsc::UnboundedReceiver<DriverCommand>,
    /// Where to report.
    pub events: EventSink,
    /// The time the driver stamps transmissions with and keeps slots by
    /// (microseconds since the epoch); the system clock unless the driver
    /// was started on another ([`Driver::spawn_with_clock`]).
    pub clock: Arc<dyn goby_time::Clock>,
}

impl std::fmt::Debug for DriverContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DriverContext")
            .field("commands", &self.commands)
            .field("events", &self.events)
            .finish_non_exhaustive()
    }
}

/// A cloneable sender of commands to a running driver.
#[derive(Debug, Clone)]
pub struct DriverHandle {
    commands: mpsc::UnboundedSender<DriverCommand>,
}

impl DriverHandle {
    /// Asks the driver to initiate a transmission.
    pub fn initiate_transmission(
        &self,
        transmission: ModemTransmission,
    ) -> Result<(), DriverError> {
        self.commands
            .send(DriverCommand::Initiate(transmission))
            .map_err(|_| DriverError::Stopped)
    }

    /// Sends a driver-specific request (a protobuf message the driver documents).
    pub fn initiate_specific(&self, request: &impl ReflectMessage) -> Result<(), DriverError> {
        self.commands
            .send(DriverCommand::Specific(request.transcode_to_dynamic()))
            .map_err(|_| DriverError::Stopped)
    }

    /// Asks the driver to acknowledge frames of a received transmission
    /// ([`DriverCommand::Acknowledge`]).
    pub fn acknowledge(&self, acknowledgement: Acknowledgement) -> Result<(), DriverError> {
        self.commands
            .send(DriverCommand::Acknowledge(acknowledgement))
            .map_err(|_| DriverError::Stopped)
    }
}

/// A running driver.
#[derive(Debug)]
pub struct Driver {
    name: &'static str,
    handle: DriverHandle,
    events: mpsc::UnboundedReceiver<DriverEvent>,
    task: JoinHandle<()>,
}

impl Driver {
    /// Spawns a driver task. `run` gets the task's [`DriverContext`] and
    /// returns when it is told to stop (or its commands are closed).
    pub fn spawn<F, Fut>(name: &'static str, run: F) -> Driver
    where
        F: FnOnce(DriverContext) -> Fut,
        Fut: std::future::Future<Output = ()> + Send + 'static,
    {
        Self::spawn_with_clock(name, Arc::new(goby_time::SystemClock), run)
    }

    /// Spawns a driver task as [`spawn`](Self::spawn) does, reading time
    /// from `clock` (e.g. one on tokio's paused clock, for tests in virtual
    /// time: see [`crate::time::TokioClock`]).
    pub fn spawn_with_clock<F, Fut>(
        name: &'static str,
        clock: Arc<dyn goby_time::Clock>,
        run: F,
    ) -> Driver
    where
        F: FnOnce(DriverContext) -> Fut,
        Fut: std::future::Future<Output = ()> + Send + 'static,
    {
        let (command_tx, command_rx) = mpsc::unbounded_channel();
        let (event_tx, event_rx) = mpsc::unbounded_channel();
        let context = DriverContext {
            commands: command_rx,
            events: EventSink { events: event_tx },
            clock,
        };
        let task = tokio::spawn(run(context));
        Driver {
            name,
            handle: DriverHandle {
                commands: command_tx,
            },
            events: event_rx,
            task,
        }
    }

    /// Name of the driver ("udp", "simulator", "micromodem", ...).
    pub fn name(&self) -> &'static str {
        self.name
    }

    /// A sender of commands usable from other tasks.
    pub fn handle(&self) -> DriverHandle {
        self.handle.clone()
    }

    /// Asks the driver to initiate a transmission.
    pub fn initiate_transmission(
        &self,
        transmission: ModemTransmission,
    ) -> Result<(), DriverError> {
        self.handle.initiate_transmission(transmission)
    }

    /// Sends a driver-specific request.
    pub fn initiate_specific(&self, request: &impl ReflectMessage) -> Result<(), DriverError> {
        self.handle.initiate_specific(request)
    }

    /// Asks the driver to acknowledge frames of a received transmission.
    pub fn acknowledge(&self, acknowledgement: Acknowledgement) -> Result<(), DriverError> {
        self.handle.acknowledge(acknowledgement)
    }

    /// The next event; `None` once the driver has stopped and every event was read.
    pub async fn next_event(&mut self) -> Option<DriverEvent> {
        self.events.recv().await
    }

    /// Stops the driver and waits for its task to end.
    pub async fn stop(self) -> Result<(), DriverError> {
        let (done_tx, done_rx) = oneshot::channel();
        if self
            .handle
            .commands
            .send(DriverCommand::Stop(done_tx))
            .is_ok()
        {
            let _ = done_rx.await;
        }
        self.task.await.map_err(|_| DriverError::Stopped)
    }
}
