//! A driver's logic as a state machine: no input or output of its own, no
//! clock read ([`Machine`]).
//!
//! Each [`Input`] — what was read from the modem, a tick, a command of the
//! layer above, the answer to a data request, the link opened or lost,
//! the driver stopping — comes with the time it happened ([`Now`]); its
//! handling returns, in order, what to do ([`Output`]: what to write,
//! events for the layer above, data requests to make, the link to open,
//! state to keep). [`Machine::next_deadline`] tells when the next
//! [`Input::Tick`] is due. Nothing in a machine waits: a data request is
//! an output and its answer a later input, and meanwhile reads, commands
//! and ticks are handled as ever. One task runs any machine on any link
//! ([`crate::shell`]); tests hand inputs in at made-up times.
//!
//! [`Outputs`] gathers a machine's outputs while it handles an input; the
//! parts most machines hold are here too: the link's reconnection
//! ([`reconnect`]), one data request at a time ([`fill`]), what a command
//! of the layer above asks and the work waiting ([`work`]), and
//! acknowledgements the drivers send as packets of their own ([`acks`]).

pub mod acks;
pub mod fill;
pub mod reconnect;
pub mod work;

use std::time::Duration;

use prost_reflect::ReflectMessage;
use protos::goby::acomms::protobuf::ModemTransmission;
use tokio::time::Instant;

use crate::driver::{
    DriverCommand, DriverEvent, DriverStatus, SpecificReport, TransmitOutcome, TransmitResult,
};

/// The time of an input, read once by the shell as the input comes, or
/// made up by a test.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Now {
    /// Monotonic time: what deadlines are kept in.
    pub at: Instant,
    /// Wall clock (UTC), microseconds since the Unix epoch: the unit of
    /// `ModemTransmission.time` and of slots, and what a modem's clock is
    /// set to.
    pub micros: u64,
}

impl Now {
    /// The time now, from both clocks: tokio's for deadlines, `clock` for
    /// stamps and slots.
    pub fn read(clock: &dyn goby_time::Clock) -> Now {
        Now {
            at: Instant::now(),
            micros: u64::try_from(clock.now()).unwrap_or(0),
        }
    }

    /// `d` later, on both clocks.
    pub fn after(self, d: Duration) -> Now {
        Now {
            at: self.at + d,
            micros: self.micros.saturating_add(d.as_micros() as u64),
        }
    }
}

/// Names a data request made by a machine ([`Output::Request`]); its
/// answer comes back with it ([`Input::Answer`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct RequestId(pub u64);

/// What happened.
#[derive(Debug)]
pub enum Input {
    /// What was read from the modem: a line without its delimiter on a
    /// link of lines, the bytes of one read on a link of bytes.
    Read(Vec<u8>),
    /// Time passed: deadlines up to now fire.
    Tick,
    /// A command of the layer above (other than `Stop`).
    Command(DriverCommand),
    /// The layer above answered a data request: the filled transmission,
    /// or `None` when the request was dropped unanswered.
    Answer {
        /// The request answered.
        id: RequestId,
        /// The transmission filled, or `None`.
        filled: Option<ModemTransmission>,
    },
    /// The link asked for by [`Output::Open`] was opened (`true`) or could
    /// not be (`false`).
    Opened(bool),
    /// The link failed (read or write): why.
    Disconnected(String),
    /// The driver stops: what is held is reported now.
    Stop,
}

/// What to do, in order.
#[derive(Debug)]
pub enum Output {
    /// Write this to the modem: a line (the link adds its delimiter) on a
    /// link of lines, bytes as they are on a link of bytes.
    Write(Vec<u8>),
    /// Give this event to the layer above.
    Event(DriverEvent),
    /// Ask the layer above to fill `template` (a data request); the
    /// answer, or its absence, comes back as [`Input::Answer`] with `id`.
    /// The machine gives up waiting on its own (a deadline): an answer
    /// after that is ignored.
    Request {
        /// Names the request in its answer.
        id: RequestId,
        /// What to fill.
        template: ModemTransmission,
    },
    /// Open the link (again), then tell [`Input::Opened`].
    Open,
    /// Keep this state for the next start (in the driver's state file),
    /// before what follows it is done.
    Keep(String),
}

/// A driver's logic, with no input or output of its own and no clock
/// read.
pub trait Machine: Send + 'static {
    /// Handles `input`, which happened at `now`; returns what to do, in
    /// order.
    fn handle(&mut self, now: Now, input: Input) -> Vec<Output>;

    /// When the next [`Input::Tick`] is due (`None`: no timer armed).
    fn next_deadline(&self) -> Option<Instant>;

    /// Whether data request `id` is still awaited (the shell forgets the
    /// answers of those that are not).
    fn awaits(&self, id: RequestId) -> bool;
}

/// A machine written as most are: a handler for each input, then the
/// work that can start ([`route`] hands an input to its handler). Every
/// such machine is a [`Machine`]: the time is set, the input routed, the
/// outputs gathered taken; the next tick is its earliest deadline.
pub trait Handlers: Send + 'static {
    /// The time of the input about to be handled.
    fn set_now(&mut self, now: Now);
    /// Where the outputs of the input being handled gather.
    fn out(&mut self) -> &mut Outputs;
    /// Its deadlines, each when armed: the earliest is when the next
    /// [`Input::Tick`] is due.
    fn deadlines(&self) -> impl IntoIterator<Item = Option<Instant>>;
    /// Whether data request `id` is still awaited.
    fn awaited(&self, id: RequestId) -> bool;
    /// What was read from the modem.
    fn read(&mut self, unit: Vec<u8>);
    /// Deadlines up to now fire.
    fn timers(&mut self);
    /// A command of the layer above.
    fn command(&mut self, command: DriverCommand);
    /// The answer to data request `id` (`None`: dropped unanswered).
    fn answered(&mut self, id: RequestId, filled: Option<ModemTransmission>);
    /// The link asked for was opened, or not.
    fn opened(&mut self, ok: bool);
    /// The link was lost: why.
    fn disconnected(&mut self, reason: String);
    /// The driver stops: what is held is reported (nothing, unless said).
    fn stop(&mut self) {}
    /// Starts the work that can start now.
    fn pump(&mut self);
}

impl<H: Handlers> Machine for H {
    fn handle(&mut self, now: Now, input: Input) -> Vec<Output> {
        self.set_now(now);
        route(self, input);
        self.out().take()
    }

    fn next_deadline(&self) -> Option<Instant> {
        self.deadlines().into_iter().flatten().min()
    }

    fn awaits(&self, id: RequestId) -> bool {
        self.awaited(id)
    }
}

/// Hands `input` to its handler, then, unless the driver stops, starts
/// the work that can start.
pub fn route(machine: &mut impl Handlers, input: Input) {
    match input {
        Input::Read(unit) => machine.read(unit),
        Input::Tick => machine.timers(),
        Input::Command(command) => machine.command(command),
        Input::Answer { id, filled } => machine.answered(id, filled),
        Input::Opened(ok) => machine.opened(ok),
        Input::Disconnected(reason) => machine.disconnected(reason),
        Input::Stop => return machine.stop(),
    }
    machine.pump();
}

/// The outputs of the input being handled, with the words a machine says
/// most.
#[derive(Debug, Default)]
pub struct Outputs(Vec<Output>);

impl Outputs {
    /// Adds `output`.
    pub fn push(&mut self, output: Output) {
        self.0.push(output);
    }

    /// Writes `unit` to the modem.
    pub fn write(&mut self, unit: Vec<u8>) {
        self.0.push(Output::Write(unit));
    }

    /// Gives `event` to the layer above.
    pub fn event(&mut self, event: DriverEvent) {
        self.0.push(Output::Event(event));
    }

    /// Reports `status`.
    pub fn status(&mut self, status: DriverStatus) {
        self.event(DriverEvent::Status(status));
    }

    /// Reports the outcome of transmission `mt`.
    pub fn result(&mut self, mt: ModemTransmission, outcome: TransmitOutcome) {
        self.event(DriverEvent::TransmitResult(TransmitResult {
            transmission: mt,
            outcome,
        }));
    }

    /// Reports a driver-specific result.
    pub fn specific(&mut self, report: &impl ReflectMessage) {
        self.event(DriverEvent::Specific(SpecificReport::new(report)));
    }

    /// The outputs so far, leaving none.
    pub fn take(&mut self) -> Vec<Output> {
        std::mem::take(&mut self.0)
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
