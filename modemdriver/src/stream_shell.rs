//! The driver task around a sans-IO driver machine that talks to its modem
//! over a byte stream (a TCP connection or a serial line): the Popoto and
//! Benthos ATM-900 drivers run in it.
//!
//! One loop waits for whichever comes first — a command of the layer
//! above, bytes from the modem, the answer to a data request, the
//! machine's next deadline — reads the clock once and hands the input to
//! the machine ([`StreamMachine::handle`]), then does its outputs in
//! order: writes bytes (a failed write is an input of its own, the link
//! lost), gives events to the layer above, makes data requests, opens the
//! link again when asked. Every chunk read and every write is reported as
//! a [`DriverEvent::Raw`].

use std::future::{poll_fn, Future};
use std::pin::Pin;
use std::sync::Arc;
use std::task::Poll;

use protos::goby::acomms::protobuf::ModemTransmission;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::oneshot;
use tokio::time::Instant;

pub use crate::evologics::driver::shell::{BoxStream, Endpoint, Stream, CONNECT_TIMEOUT};
pub use crate::micromodem::driver::machine::{Now, RequestId};

use crate::driver::{
    DataRequest, Driver, DriverCommand, DriverContext, DriverEvent, DriverStatus, EventSink,
    RawDirection, RawMessage,
};
use crate::micromodem::driver::shell::now;
use crate::time::sleep_until_opt;

/// What happened, as a machine is told.
#[derive(Debug)]
pub enum Input {
    /// Bytes read from the modem.
    Bytes(Vec<u8>),
    /// Time passed: deadlines up to now fire.
    Tick,
    /// A command of the layer above (other than `Stop`).
    Command(DriverCommand),
    /// The layer above answered a data request (`None`: dropped).
    Answer {
        /// The request answered.
        id: RequestId,
        /// The transmission filled, or `None`.
        filled: Option<ModemTransmission>,
    },
    /// The link asked for by [`Output::Open`] was opened (`true`) or not.
    Opened(bool),
    /// The link failed: why.
    Disconnected(String),
}

/// What a machine asks to be done, in order.
#[derive(Debug)]
pub enum Output {
    /// Write these bytes to the modem.
    Write(Vec<u8>),
    /// Give this event to the layer above.
    Event(DriverEvent),
    /// Ask the layer above to fill `template`; the answer comes back as
    /// [`Input::Answer`] with `id`.
    Request {
        /// Names the request.
        id: RequestId,
        /// What to fill.
        template: ModemTransmission,
    },
    /// Open the link again, then tell [`Input::Opened`].
    Open,
}

/// A driver's logic, with no input or output of its own and no clock read.
pub trait StreamMachine: Send + 'static {
    /// Handles `input`, which happened at `now`; returns what to do.
    fn handle(&mut self, now: Now, input: Input) -> Vec<Output>;
    /// When the next [`Input::Tick`] is due.
    fn next_deadline(&self) -> Option<Instant>;
    /// Whether data request `id` is still awaited.
    fn awaits(&self, id: RequestId) -> bool;
}

/// Spawns the driver task `name` running `machine` on `link` (`None`: not
/// open yet; the machine asks to open `endpoint`), reading time from
/// `clock`. A machine started without a link reports
/// [`DriverStatus::Disconnected`] first.
pub fn spawn<M: StreamMachine>(
    name: &'static str,
    machine: M,
    endpoint: Endpoint,
    link: Option<BoxStream>,
    clock: Arc<dyn goby_time::Clock>,
) -> Driver {
    Driver::spawn_with_clock(name, clock, move |ctx| {
        if link.is_none() {
            ctx.events.status(DriverStatus::Disconnected {
                reason: format!("no connection to {} yet", endpoint.describe()),
            });
        }
        run(machine, endpoint, link, ctx)
    })
}

type Answers = Vec<(RequestId, oneshot::Receiver<ModemTransmission>)>;

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

async fn read_opt(link: &mut Option<BoxStream>, buf: &mut [u8]) -> std::io::Result<usize> {
    match link {
        Some(l) => l.read(buf).await,
        None => std::future::pending().await,
    }
}

struct Shell<M> {
    machine: M,
    link: Option<BoxStream>,
    endpoint: Endpoint,
    events: EventSink,
    answers: Answers,
    clock: Arc<dyn goby_time::Clock>,
}

/// The driver task, on `link` when it is open already.
pub async fn run<M: StreamMachine>(
    machine: M,
    endpoint: Endpoint,
    link: Option<BoxStream>,
    mut ctx: DriverContext,
) {
    let mut shell = Shell {
        machine,
        link,
        endpoint,
        events: ctx.events.clone(),
        answers: Vec::new(),
        clock: ctx.clock.clone(),
    };
    let mut input = Input::Tick;
    let mut buf = vec![0u8; 2048];
    loop {
        shell.step(input).await;
        let wake = shell.machine.next_deadline();
        input = tokio::select! {
            command = ctx.commands.recv() => match command {
                Some(DriverCommand::Stop(done)) => {
                    let _ = done.send(());
                    return;
                }
                Some(c) => Input::Command(c),
                None => return,
            },
            read = read_opt(&mut shell.link, &mut buf) => match read {
                Ok(0) => {
                    shell.link = None;
                    Input::Disconnected(format!("{} closed", shell.endpoint.describe()))
                }
                Ok(n) => {
                    shell.events.emit(DriverEvent::Raw(RawMessage {
                        direction: RawDirection::Incoming,
                        bytes: buf[..n].to_vec(),
                        peer: None,
                    }));
                    Input::Bytes(buf[..n].to_vec())
                }
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

impl<M: StreamMachine> Shell<M> {
    async fn step(&mut self, input: Input) {
        let outputs = self.machine.handle(now(&*self.clock), input);
        let mut queue: std::collections::VecDeque<Output> = outputs.into();
        while let Some(output) = queue.pop_front() {
            match output {
                Output::Write(bytes) => {
                    let Some(l) = self.link.as_mut() else {
                        continue;
                    };
                    let written = async {
                        l.write_all(&bytes).await?;
                        l.flush().await
                    }
                    .await;
                    match written {
                        Ok(()) => self.events.emit(DriverEvent::Raw(RawMessage {
                            direction: RawDirection::Outgoing,
                            bytes,
                            peer: None,
                        })),
                        Err(e) => {
                            self.link = None;
                            let failed = Input::Disconnected(format!("write failed: {e}"));
                            queue.extend(self.machine.handle(now(&*self.clock), failed));
                        }
                    }
                }
                Output::Event(event) => self.events.emit(event),
                Output::Request { id, template } => {
                    let (request, answer) = DataRequest::new(template);
                    self.answers.push((id, answer));
                    self.events.emit(DriverEvent::DataRequest(request));
                }
                Output::Open => {
                    let opened = match self.endpoint.open().await {
                        Ok(l) => {
                            self.link = Some(l);
                            true
                        }
                        Err(e) => {
                            tracing::debug!("{}: {e}", self.endpoint.describe());
                            false
                        }
                    };
                    queue.extend(
                        self.machine
                            .handle(now(&*self.clock), Input::Opened(opened)),
                    );
                }
            }
        }
        let machine = &self.machine;
        self.answers.retain(|(id, _)| machine.awaits(*id));
    }
}

/// Text of at most `max` characters of `bytes` (lossy UTF-8, control
/// characters escaped), for statuses.
pub fn lossy(bytes: &[u8], max: usize) -> String {
    let text: String = String::from_utf8_lossy(bytes)
        .chars()
        .flat_map(|c| {
            if c.is_control() {
                c.escape_default().collect::<Vec<_>>()
            } else {
                vec![c]
            }
        })
        .collect();
    if text.chars().count() > max {
        let cut: String = text.chars().take(max).collect();
        format!("{cut}…")
    } else {
        text
    }
}
