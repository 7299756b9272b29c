//! The driver task: the [`Machine`]'s inputs and outputs over a TCP
//! connection or a serial line.
//!
//! One loop waits for whichever comes first — a command of the layer
//! above, bytes from the modem, the answer to a data request, the
//! machine's next deadline — reads the clock once and hands the input to
//! the machine, then does its outputs in order: writes bytes (a failed
//! write is an input of its own, the link lost), gives events to the layer
//! above, makes data requests, opens the link again when asked. Every chunk
//! read and every command written is reported as a
//! [`DriverEvent::Raw`].

use std::future::{poll_fn, Future};
use std::pin::Pin;
use std::sync::Arc;
use std::task::Poll;
use std::time::Duration;

use protos::goby::acomms::protobuf::ModemTransmission;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::sync::oneshot;

use super::machine::{Input, Machine, Output, RequestId};
use crate::driver::{
    DataRequest, DriverCommand, DriverContext, DriverEvent, EventSink, RawDirection, RawMessage,
};
use crate::micromodem::driver::shell::now;
use crate::time::sleep_until_opt;

/// A byte stream to the modem.
pub trait Stream: AsyncRead + AsyncWrite + Unpin + Send {}
impl<T: AsyncRead + AsyncWrite + Unpin + Send> Stream for T {}

/// A boxed byte stream to the modem.
pub type BoxStream = Box<dyn Stream>;

/// How to reach the modem (again).
#[derive(Debug, Clone)]
pub enum Endpoint {
    /// A TCP server (the modem's Ethernet interface), `host:port`.
    Tcp(String),
    /// A serial line (or pseudo-terminal) at a baud rate.
    Serial {
        /// Device path.
        path: String,
        /// Baud rate.
        baud: u32,
    },
}

/// Longest a TCP connection attempt waits.
pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(5);

impl Endpoint {
    /// Opens the link.
    pub async fn open(&self) -> std::io::Result<BoxStream> {
        match self {
            Endpoint::Tcp(addr) => {
                let stream =
                    tokio::time::timeout(CONNECT_TIMEOUT, tokio::net::TcpStream::connect(addr))
                        .await
                        .map_err(|_| {
                            std::io::Error::new(
                                std::io::ErrorKind::TimedOut,
                                format!("no connection to {addr} within {CONNECT_TIMEOUT:?}"),
                            )
                        })??;
                let _ = stream.set_nodelay(true);
                Ok(Box::new(stream))
            }
            Endpoint::Serial { path, baud } => {
                use tokio_serial::SerialPortBuilderExt;
                let s = tokio_serial::new(path, *baud)
                    .open_native_async()
                    .map_err(|e| std::io::Error::other(format!("cannot open {path}: {e}")))?;
                Ok(Box::new(s))
            }
        }
    }

    /// Where, in words.
    pub fn describe(&self) -> String {
        match self {
            Endpoint::Tcp(a) => format!("tcp {a}"),
            Endpoint::Serial { path, .. } => path.clone(),
        }
    }
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

struct Shell {
    machine: Machine,
    link: Option<BoxStream>,
    endpoint: Endpoint,
    events: EventSink,
    answers: Answers,
    clock: Arc<dyn goby_time::Clock>,
}

/// The driver task, on `link` when it is open already.
pub(super) async fn run(
    machine: Machine,
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

impl Shell {
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
