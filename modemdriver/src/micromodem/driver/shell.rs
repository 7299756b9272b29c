//! The driver task: the [`Machine`]'s inputs and outputs.
//!
//! One loop waits for whichever comes first: a command of the layer above,
//! a line from the serial link, the answer to a data request outstanding,
//! or the machine's next deadline. It reads the clock once ([`now`])
//! and hands the input to the machine, then does the outputs in order:
//! writes lines (a failed write is an input of its own, the link lost),
//! gives events to the layer above, makes data requests (each answer, or
//! its sender dropped, comes back as an input; requests the machine gave
//! up are forgotten), and opens the device again when asked. Nothing else
//! waits: a data request outstanding leaves the loop reading lines, taking
//! commands and firing timers.

use std::future::{poll_fn, Future};
use std::pin::Pin;
use std::task::Poll;

use protos::goby::acomms::protobuf::ModemTransmission;
use tokio::sync::oneshot;

use std::sync::Arc;

use super::machine::{Input, Machine, Now, Output, RequestId, Settings};
use crate::driver::{DataRequest, DriverCommand, DriverContext, DriverEvent, EventSink};
use crate::link::fault::{FaultConfig, FaultInjector, FaultScript};
use crate::link::serial::{self, SerialLineLink};
use crate::link::trace::Tracer;
use crate::link::Link;
use crate::time::sleep_until_opt;

/// The time now, from both clocks (tokio's for timers, the driver's
/// clock for stamps and slots): the one clock read of the driver.
pub fn now(clock: &dyn goby_time::Clock) -> Now {
    Now {
        at: tokio::time::Instant::now(),
        micros: u64::try_from(clock.now()).unwrap_or(0),
    }
}

type MmLink = Tracer<FaultInjector<SerialLineLink>>;

/// Everything needed to open the serial device (again).
#[derive(Debug, Clone)]
pub struct Port {
    /// The serial device.
    pub path: String,
    /// Its baud rate.
    pub baud: u32,
    /// What ends a line.
    pub delimiter: Vec<u8>,
    /// Random faults injected on the lines read (tests, bench work).
    pub faults: FaultConfig,
    /// Scripted faults injected on the lines read.
    pub script: FaultScript,
}

impl Port {
    fn open(&self, sink: &EventSink) -> std::io::Result<MmLink> {
        let lines = serial::open(&self.path, self.baud, &self.delimiter)?;
        Ok(self.wrap(lines, sink))
    }

    fn wrap(&self, lines: SerialLineLink, sink: &EventSink) -> MmLink {
        Tracer::new(
            FaultInjector::new(lines, self.faults.clone(), self.script.clone()),
            sink.clone(),
        )
    }
}

async fn recv_opt(link: &mut Option<MmLink>) -> std::io::Result<Vec<u8>> {
    match link {
        Some(link) => link.recv().await.map(|(line, ())| line),
        None => std::future::pending().await,
    }
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

/// The driver task.
pub(super) async fn run(
    settings: Settings,
    port: Port,
    lines: SerialLineLink,
    mut ctx: DriverContext,
) {
    let events = ctx.events.clone();
    let clock = ctx.clock.clone();
    let mut settings = settings;
    let ack_state_file = settings.ack_state_file.take();
    let machine = Machine::new(settings, now(&*clock));
    let mut shell = Shell {
        link: Some(port.wrap(lines, &events)),
        machine,
        port,
        events,
        answers: Vec::new(),
        clock,
        ack_state_file,
    };
    let mut input = Input::Tick;
    loop {
        shell.step(input).await;
        let wake = shell.machine.next_deadline();
        input = tokio::select! {
            command = ctx.commands.recv() => match command {
                Some(DriverCommand::Stop(done)) => {
                    shell.step(Input::Stop).await;
                    let _ = done.send(());
                    return;
                }
                Some(command) => Input::Command(command),
                None => return,
            },
            line = recv_opt(&mut shell.link) => match line {
                Ok(line) => Input::Line(line),
                Err(e) => {
                    shell.link = None;
                    Input::Disconnected(format!("read failed: {e}"))
                }
            },
            (id, filled) = next_answer(&mut shell.answers), if !shell.answers.is_empty() => {
                Input::Answer { id, filled }
            }
            () = sleep_until_opt(wake) => Input::Tick,
        };
    }
}

/// What the driver task holds: the machine and the parts it acts through.
struct Shell {
    machine: Machine,
    link: Option<MmLink>,
    port: Port,
    events: EventSink,
    /// Data requests outstanding, with where their answers come.
    answers: Answers,
    /// Where [`Output::KeepAckState`] is written.
    ack_state_file: Option<std::path::PathBuf>,
    clock: Arc<dyn goby_time::Clock>,
}

impl Shell {
    /// Hands `input` to the machine, reading the clock once, and does its
    /// outputs, in order, and those of the inputs they cause (a write that
    /// fails, the device opened or not); forgets the answers the machine no
    /// longer waits for.
    async fn step(&mut self, input: Input) {
        let outputs = self.machine.handle(now(&*self.clock), input);
        let mut queue: std::collections::VecDeque<Output> = outputs.into();
        while let Some(output) = queue.pop_front() {
            match output {
                Output::Write(sentence) => {
                    // Lines for a link that failed since are not written.
                    let Some(l) = self.link.as_mut() else {
                        continue;
                    };
                    if let Err(e) = l.send(sentence.to_line().as_bytes(), &()).await {
                        self.link = None;
                        let failed = Input::Disconnected(format!("write failed: {e}"));
                        queue.extend(self.machine.handle(now(&*self.clock), failed));
                    }
                }
                Output::Event(event) => self.events.emit(event),
                Output::Request { id, template } => {
                    let (request, answer) = DataRequest::new(template);
                    self.answers.push((id, answer));
                    self.events.emit(DriverEvent::DataRequest(request));
                }
                Output::KeepAckState(state) => {
                    if let Some(path) = &self.ack_state_file {
                        keep_ack_state(path, &state);
                    }
                }
                Output::Open => {
                    let opened = match self.port.open(&self.events) {
                        Ok(l) => {
                            self.link = Some(l);
                            true
                        }
                        Err(_) => false,
                    };
                    let input = Input::Opened(opened);
                    queue.extend(self.machine.handle(now(&*self.clock), input));
                }
            }
        }
        let machine = &self.machine;
        self.answers.retain(|(id, _)| machine.awaits(*id));
    }
}

/// Writes the application-ack state to `path` whole (a file beside it,
/// synced, then renamed over it). When that fails (e.g. a full disk) the
/// file is emptied instead, so that the next start, finding no state it can
/// read, credits acks only from nodes heard from (see
/// [`ApplicationAcks::resume`](crate::micromodem::application_ack::ApplicationAcks::resume)).
fn keep_ack_state(path: &std::path::Path, state: &str) {
    use std::io::Write;
    let write = || -> std::io::Result<()> {
        let mut next = path.as_os_str().to_owned();
        next.push(".next");
        let next = std::path::PathBuf::from(next);
        let mut file = std::fs::File::create(&next)?;
        file.write_all(state.as_bytes())?;
        file.sync_all()?;
        std::fs::rename(&next, path)?;
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::File::open(dir)?.sync_all()?;
        }
        Ok(())
    };
    if let Err(e) = write() {
        tracing::warn!(
            "application acks: keeping the frame numbers in {}: {e}; after a restart, acks \
             are credited only from nodes heard from",
            path.display()
        );
        if let Ok(file) = std::fs::OpenOptions::new().write(true).open(path) {
            let _ = file.set_len(0);
            let _ = file.sync_all();
        }
    }
}
