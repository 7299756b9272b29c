//! The one driver task: any [`Machine`] over a modem's stream (TCP, a
//! serial port, a pseudo-terminal), read as lines or as bytes.
//!
//! One loop waits for whichever comes first — a command of the layer
//! above, what the link reads, the answer to a data request, the machine's
//! next deadline — reads the clock once ([`Now::read`]) and hands the
//! input to the machine, then does its outputs in order: writes (a failed
//! write is an input of its own, the link lost), gives events to the layer
//! above, makes data requests (each answer, or its request dropped, comes
//! back as an input; requests the machine gave up are forgotten), opens
//! the link again when asked, keeps the machine's state in its file.
//! Nothing else waits: a data request outstanding leaves the loop reading,
//! taking commands and firing timers.
//!
//! The link is wrapped as every driver's is: faults injected on what is
//! read ([`crate::link::fault`], none unless asked for: tests and bench
//! work), and every read and write reported as a
//! [`crate::DriverEvent::Raw`] ([`crate::link::trace`]).

use std::future::{poll_fn, Future};
use std::path::PathBuf;
use std::pin::Pin;
use std::sync::Arc;
use std::task::Poll;

use protos::goby::acomms::protobuf::ModemTransmission;
use tokio::sync::oneshot;

use crate::driver::{
    DataRequest, Driver, DriverCommand, DriverContext, DriverError, DriverEvent, DriverStatus,
    EventSink,
};
use crate::link::fault::{FaultConfig, FaultInjector, FaultScript};
use crate::link::stream::{BoxStream, Endpoint, StreamLink, Units};
use crate::link::trace::Tracer;
use crate::link::Link;
use crate::machine::{Input, Machine, Now, Output, RequestId};
use crate::time::sleep_until_opt;

/// A modem's link: where it is, how it is read, and the faults injected
/// on what is read.
#[derive(Debug, Clone)]
pub struct Device {
    /// Where the modem is.
    pub endpoint: Endpoint,
    /// Lines or bytes.
    pub units: Units,
    /// Random faults injected on what is read (tests, bench work).
    pub faults: FaultConfig,
    /// Scripted faults injected on what is read.
    pub script: FaultScript,
}

impl Device {
    /// `endpoint` read as `units`, with no faults.
    pub fn new(endpoint: Endpoint, units: Units) -> Device {
        Device {
            endpoint,
            units,
            faults: FaultConfig::default(),
            script: FaultScript::new(),
        }
    }

    fn wrap(&self, stream: BoxStream, sink: &EventSink) -> DeviceLink {
        Tracer::new(
            FaultInjector::new(
                StreamLink::new(stream, &self.units),
                self.faults.clone(),
                self.script.clone(),
            ),
            sink.clone(),
        )
    }
}

type DeviceLink = Tracer<FaultInjector<StreamLink>>;

/// What the task is started with besides its machine.
pub struct Start {
    /// The task's name ("popoto", ...).
    pub name: &'static str,
    /// The modem's link.
    pub device: Device,
    /// The link, when open already (`None`: the machine, started
    /// disconnected, asks to open it).
    pub stream: Option<BoxStream>,
    /// Where [`Output::Keep`] state goes (none: it is not kept).
    pub keep: Option<PathBuf>,
    /// The clock stamps and slots are read from.
    pub clock: Arc<dyn goby_time::Clock>,
}

/// Starts the driver `name` on the serial line of `device`, which must be
/// there now (a path named wrongly is an error at start); `machine(now)`
/// makes its machine, `keep` is where its state is kept, `clock` what
/// stamps and slots are read from.
///
/// # Errors
/// [`DriverError::Io`] naming `DriverConfig.serial_port` when the line
/// cannot be opened.
pub fn start_on_serial<M: Machine>(
    name: &'static str,
    device: Device,
    machine: impl FnOnce(Now) -> M,
    keep: Option<PathBuf>,
    clock: Arc<dyn goby_time::Clock>,
) -> Result<Driver, DriverError> {
    let stream = device
        .endpoint
        .open_serial()
        .map_err(|e| DriverError::io("DriverConfig.serial_port", e))?;
    let machine = machine(Now::read(&*clock));
    Ok(spawn(
        machine,
        Start {
            name,
            device,
            stream: Some(stream),
            keep,
            clock,
        },
    ))
}

/// Opens `device` if it can now; a modem that cannot be reached yet is
/// not an error (the driver reports itself disconnected and tries again
/// every reconnection interval).
pub async fn open_if_there(device: &Device, driver: &str) -> Option<BoxStream> {
    match device.endpoint.open().await {
        Ok(stream) => Some(stream),
        Err(e) => {
            tracing::warn!("{driver}: modem at {}: {e}", device.endpoint.describe());
            None
        }
    }
}

/// Starts the driver `name` on `device`: open now if the modem can be
/// reached, else the driver reports itself disconnected and opens it every
/// reconnection interval. `machine(now, connected)` makes its machine.
pub async fn start_reconnecting<M: Machine>(
    name: &'static str,
    device: Device,
    machine: impl FnOnce(Now, bool) -> M,
) -> Driver {
    let stream = open_if_there(&device, name).await;
    let clock: Arc<dyn goby_time::Clock> = Arc::new(goby_time::SystemClock);
    let machine = machine(Now::read(&*clock), stream.is_some());
    spawn(
        machine,
        Start {
            name,
            device,
            stream,
            keep: None,
            clock,
        },
    )
}

/// Spawns the driver task running `machine` (made with its link open
/// when `start.stream` is, disconnected otherwise).
pub fn spawn<M: Machine>(machine: M, start: Start) -> Driver {
    let Start {
        name,
        device,
        stream,
        keep,
        clock,
    } = start;
    Driver::spawn_with_clock(name, clock, move |ctx| {
        if stream.is_none() {
            ctx.events.status(DriverStatus::Disconnected {
                reason: format!("no connection to {} yet", device.endpoint.describe()),
            });
        }
        run(machine, device, stream, keep, ctx)
    })
}

/// Data requests outstanding: their answers to come.
type Answers = Vec<(RequestId, oneshot::Receiver<ModemTransmission>)>;

/// The first answer to come (`None`: its request was dropped); pending
/// while there is none outstanding.
async fn next_answer(answers: &mut Answers) -> (RequestId, Option<ModemTransmission>) {
    poll_fn(|cx| {
        for i in 0..answers.len() {
            if let Poll::Ready(answer) = Pin::new(&mut answers[i].1).poll(cx) {
                let (id, _) = answers.swap_remove(i);
                return Poll::Ready((id, answer.ok()));
            }
        }
        Poll::Pending
    })
    .await
}

async fn recv_opt(link: &mut Option<DeviceLink>) -> std::io::Result<Vec<u8>> {
    match link {
        Some(link) => link.recv().await.map(|(unit, ())| unit),
        None => std::future::pending().await,
    }
}

/// What the task holds: the machine and the parts it acts through.
struct Shell<M> {
    machine: M,
    link: Option<DeviceLink>,
    device: Device,
    events: EventSink,
    answers: Answers,
    keep: Option<PathBuf>,
    clock: Arc<dyn goby_time::Clock>,
}

async fn run<M: Machine>(
    machine: M,
    device: Device,
    stream: Option<BoxStream>,
    keep: Option<PathBuf>,
    mut ctx: DriverContext,
) {
    let events = ctx.events.clone();
    let mut shell = Shell {
        link: stream.map(|s| device.wrap(s, &events)),
        machine,
        device,
        events,
        answers: Vec::new(),
        keep,
        clock: ctx.clock.clone(),
    };
    let mut input = Input::Tick;
    loop {
        shell.step(input).await;
        let wake = shell.machine.next_deadline();
        // Biased: inputs ready at the same instant (of a simulation's virtual
        // clock, or under load) are taken in this order, not at random, so that
        // the same inputs give the same outputs. Commands and answers first (they
        // come at the daemon's pace); the machine's deadline before the device's
        // bytes, so that a device sending without pause cannot hold a timeout
        // back (the deadline is ready once, the reads may be ready every turn).
        input = tokio::select! {
            biased;
            command = ctx.commands.recv() => match command {
                Some(DriverCommand::Stop(done)) => {
                    shell.step(Input::Stop).await;
                    let _ = done.send(());
                    return;
                }
                Some(command) => Input::Command(command),
                None => return,
            },
            (id, filled) = next_answer(&mut shell.answers), if !shell.answers.is_empty() => {
                Input::Answer { id, filled }
            }
            () = sleep_until_opt(wake) => Input::Tick,
            read = recv_opt(&mut shell.link) => match read {
                Ok(unit) => Input::Read(unit),
                Err(e) => {
                    shell.link = None;
                    Input::Disconnected(match e.kind() {
                        std::io::ErrorKind::UnexpectedEof => {
                            format!("{} closed", shell.device.endpoint.describe())
                        }
                        _ => format!("read failed: {e}"),
                    })
                }
            },
        };
    }
}

impl<M: Machine> Shell<M> {
    /// Hands `input` to the machine, reading the clock once, and does its
    /// outputs, in order, and those of the inputs they cause (a write that
    /// fails, the link opened or not); forgets the answers the machine no
    /// longer waits for.
    async fn step(&mut self, input: Input) {
        let outputs = self.machine.handle(Now::read(&*self.clock), input);
        let mut queue: std::collections::VecDeque<Output> = outputs.into();
        while let Some(output) = queue.pop_front() {
            match output {
                Output::Write(unit) => {
                    // Writes for a link that failed since are not made.
                    let Some(link) = self.link.as_mut() else {
                        continue;
                    };
                    if let Err(e) = link.send(&unit, &()).await {
                        self.link = None;
                        let failed = Input::Disconnected(format!("write failed: {e}"));
                        queue.extend(self.machine.handle(Now::read(&*self.clock), failed));
                    }
                }
                Output::Event(event) => self.events.emit(event),
                Output::Request { id, template } => {
                    let (request, answer) = DataRequest::new(template);
                    self.answers.push((id, answer));
                    self.events.emit(DriverEvent::DataRequest(request));
                }
                Output::Keep(state) => {
                    if let Some(path) = &self.keep {
                        keep(path, &state);
                    }
                }
                Output::Open => {
                    let opened = match self.device.endpoint.open().await {
                        Ok(stream) => {
                            self.link = Some(self.device.wrap(stream, &self.events));
                            true
                        }
                        Err(e) => {
                            tracing::debug!("{}: {e}", self.device.endpoint.describe());
                            false
                        }
                    };
                    let input = Input::Opened(opened);
                    queue.extend(self.machine.handle(Now::read(&*self.clock), input));
                }
            }
        }
        let machine = &self.machine;
        self.answers.retain(|(id, _)| machine.awaits(*id));
    }
}

/// Writes `state` to `path` whole ([`goby_store::file::write_atomically`]). When
/// that fails (e.g. a full disk) the file is emptied instead, so that the
/// next start, finding no state it can read, starts afresh rather than
/// from a state that is no longer true.
fn keep(path: &std::path::Path, state: &str) {
    if let Err(e) = goby_store::file::write_atomically(path, state.as_bytes()) {
        tracing::warn!(
            "keeping the driver's state in {}: {e}; the next start begins afresh",
            path.display()
        );
        if let Ok(file) = std::fs::OpenOptions::new().write(true).open(path) {
            let _ = file.set_len(0);
            let _ = file.sync_all();
        }
    }
}
