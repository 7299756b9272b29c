//! The driver task: the [`Machine`]'s inputs and outputs over a serial
//! port.
//!
//! One loop waits for whichever comes first: a command of the layer above,
//! bytes from the port, the answer to a data request outstanding, or the
//! machine's next deadline; it reads the clock once per input and does the
//! machine's outputs in order (a write that fails is an input of its own,
//! the link lost).

use std::future::{poll_fn, Future};
use std::pin::Pin;
use std::sync::Arc;
use std::task::Poll;

use protos::goby::acomms::protobuf::ModemTransmission;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::oneshot;
use tokio_serial::{SerialPort, SerialPortBuilderExt, SerialStream};

use super::machine::{Input, Machine, Now, Output, RequestId, Settings};
use crate::driver::{DataRequest, DriverCommand, DriverContext, DriverEvent, EventSink};
use crate::time::sleep_until_opt;

/// The time now, from both clocks (tokio's for timers, the driver's clock
/// for stamps).
pub fn now(clock: &dyn goby_time::Clock) -> Now {
    Now {
        at: tokio::time::Instant::now(),
        micros: u64::try_from(clock.now()).unwrap_or(0),
    }
}

/// The serial port to open (again).
#[derive(Debug, Clone)]
pub struct Port {
    /// The device (or pseudo-terminal).
    pub path: String,
    /// Its baud rate.
    pub baud: u32,
    /// Raise DTR once open.
    pub dtr: bool,
}

impl Port {
    /// Opens the port, 8N1, no flow control.
    pub fn open(&self) -> std::io::Result<SerialStream> {
        let mut stream = tokio_serial::new(&self.path, self.baud)
            .open_native_async()
            .map_err(|e| {
                std::io::Error::other(format!("cannot open serial port {}: {e}", self.path))
            })?;
        if self.dtr {
            // A pseudo-terminal has no DTR line: not an error.
            let _ = stream.write_data_terminal_ready(true);
        }
        Ok(stream)
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

async fn read_opt(stream: &mut Option<SerialStream>, buf: &mut [u8]) -> std::io::Result<usize> {
    match stream {
        Some(s) => match s.read(buf).await {
            Ok(0) => Err(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                "the device closed",
            )),
            other => other,
        },
        None => std::future::pending().await,
    }
}

/// The driver task.
pub(super) async fn run(
    settings: Settings,
    port: Port,
    stream: SerialStream,
    mut ctx: DriverContext,
) {
    let clock = ctx.clock.clone();
    let mut shell = Shell {
        machine: Machine::new(settings, now(&*clock)),
        stream: Some(stream),
        port,
        events: ctx.events.clone(),
        answers: Vec::new(),
        clock,
    };
    let mut buf = vec![0u8; 1024];
    let mut input = Input::Tick;
    loop {
        shell.step(input).await;
        let wake = shell.machine.next_deadline();
        input = tokio::select! {
            command = ctx.commands.recv() => match command {
                Some(DriverCommand::Stop(done)) => {
                    let _ = done.send(());
                    return;
                }
                Some(command) => Input::Command(command),
                None => return,
            },
            read = read_opt(&mut shell.stream, &mut buf) => match read {
                Ok(n) => Input::Bytes(buf[..n].to_vec()),
                Err(e) => {
                    shell.stream = None;
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

struct Shell {
    machine: Machine,
    stream: Option<SerialStream>,
    port: Port,
    events: EventSink,
    answers: Answers,
    clock: Arc<dyn goby_time::Clock>,
}

impl Shell {
    async fn step(&mut self, input: Input) {
        let outputs = self.machine.handle(now(&*self.clock), input);
        let mut queue: std::collections::VecDeque<Output> = outputs.into();
        while let Some(output) = queue.pop_front() {
            match output {
                Output::Write(bytes) => {
                    let Some(s) = self.stream.as_mut() else {
                        continue;
                    };
                    let written = async {
                        s.write_all(&bytes).await?;
                        s.flush().await
                    }
                    .await;
                    if let Err(e) = written {
                        self.stream = None;
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
                Output::Open => {
                    let opened = match self.port.open() {
                        Ok(s) => {
                            self.stream = Some(s);
                            true
                        }
                        Err(_) => false,
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
