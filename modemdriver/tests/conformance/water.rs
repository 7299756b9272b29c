//! Two drivers' machines and their two emulated modems, coupled sans I/O
//! and run in virtual time: what a machine writes its modem reads, what
//! the modem says its machine reads, and what a modem puts on the water
//! the other hears after the sound's travel time. Nothing waits: time
//! jumps to the next deadline of a machine, a modem or a packet on the
//! water.

use std::collections::VecDeque;
use std::time::Duration;

use emulators::host::{EmulatedModem, EmulatorControl, Shared};
use modemdriver::machine::{Input, Machine, Now, Output};
use modemdriver::{DriverCommand, DriverEvent, DriverStatus, ModemTransmission};
use tokio::time::Instant;

/// An emulated modem whatever it counts.
pub trait Emulated: Send {
    fn host(&mut self, bytes: &[u8], now: Instant);
    fn water(&mut self, mt: &ModemTransmission, now: Instant);
    fn timers(&mut self, now: Instant);
    fn next_deadline(&self) -> Option<Instant>;
    fn shared(&mut self) -> &mut Shared;
    fn connected(&mut self);
}

impl<T: EmulatedModem> Emulated for T {
    fn host(&mut self, bytes: &[u8], now: Instant) {
        EmulatedModem::host(self, bytes, now)
    }
    fn water(&mut self, mt: &ModemTransmission, now: Instant) {
        EmulatedModem::water(self, mt, now)
    }
    fn timers(&mut self, now: Instant) {
        EmulatedModem::timers(self, now)
    }
    fn next_deadline(&self) -> Option<Instant> {
        EmulatedModem::next_deadline(self)
    }
    fn shared(&mut self) -> &mut Shared {
        EmulatedModem::shared(self)
    }
    fn connected(&mut self) {
        EmulatedModem::connected(self)
    }
}

/// One node: a driver's machine and its modem.
pub struct Node {
    pub machine: Box<dyn Machine>,
    pub modem: Box<dyn Emulated>,
    /// Inputs for the machine, in order.
    inputs: VecDeque<Input>,
    /// What the machine reported, in order (data requests answered).
    pub events: Vec<DriverEvent>,
    /// Frames the layer above answers data requests with.
    pub frames: Vec<Vec<u8>>,
    /// The link is down (after [`Water::drop_link`]) until opened.
    down: bool,
}

/// The two nodes, the water between them, and the time.
pub struct Water {
    pub now: Now,
    pub nodes: [Node; 2],
    /// Packets on the water: when heard, by which node.
    in_flight: Vec<(Instant, usize, ModemTransmission)>,
    /// Time the sound takes between the two modems.
    pub travel: Duration,
}

impl Water {
    pub fn new(
        now: Now,
        nodes: [(Box<dyn Machine>, Box<dyn Emulated>); 2],
        travel: Duration,
    ) -> Water {
        let nodes = nodes.map(|(machine, mut modem)| {
            modem.connected();
            Node {
                machine,
                modem,
                inputs: VecDeque::from([Input::Tick]),
                events: Vec::new(),
                frames: Vec::new(),
                down: false,
            }
        });
        Water {
            now,
            nodes,
            in_flight: Vec::new(),
            travel,
        }
    }

    /// Hands node `i`'s driver a command.
    pub fn command(&mut self, i: usize, command: DriverCommand) {
        self.nodes[i].inputs.push_back(Input::Command(command));
    }

    /// A fault of node `i`'s modem, on demand.
    pub fn control(&mut self, i: usize, control: EmulatorControl) {
        self.nodes[i].modem.shared().control(control);
    }

    /// Node `i`'s link drops (its driver reads an end); the driver opens
    /// it again when it asks.
    pub fn drop_link(&mut self, i: usize) {
        self.nodes[i].down = true;
        self.nodes[i]
            .inputs
            .push_back(Input::Disconnected("the connection dropped".into()));
    }

    /// Runs until `done` holds of the nodes, or `limit` of virtual time
    /// passes (`false` then).
    pub fn run_until(&mut self, limit: Duration, mut done: impl FnMut(&[Node; 2]) -> bool) -> bool {
        let end = self.now.at + limit;
        for _ in 0..100_000 {
            if done(&self.nodes) {
                return true;
            }
            if self.step() {
                continue;
            }
            let next = self
                .nodes
                .iter()
                .flat_map(|n| [n.machine.next_deadline(), n.modem.next_deadline()])
                .chain(self.in_flight.iter().map(|(at, _, _)| Some(*at)))
                .flatten()
                .min();
            let Some(next) = next.filter(|&t| t <= end) else {
                return done(&self.nodes);
            };
            self.now = self.now.after(next.saturating_duration_since(self.now.at));
            self.fire();
        }
        panic!("no end after 100000 steps");
    }

    /// Fires what is due now.
    fn fire(&mut self) {
        let now = self.now.at;
        let (due, rest): (Vec<_>, Vec<_>) =
            self.in_flight.drain(..).partition(|(at, ..)| *at <= now);
        self.in_flight = rest;
        for (_, to, mt) in due {
            self.nodes[to].modem.water(&mt, now);
        }
        for node in &mut self.nodes {
            node.modem.timers(now);
            node.inputs.push_back(Input::Tick);
        }
    }

    /// Moves what is ready without time passing; `true` when something
    /// moved.
    fn step(&mut self) -> bool {
        let mut moved = false;
        for i in 0..2 {
            while let Some(input) = self.nodes[i].inputs.pop_front() {
                moved = true;
                let outputs = self.nodes[i].machine.handle(self.now, input);
                self.outputs(i, outputs);
            }
            let node = &mut self.nodes[i];
            let said = std::mem::take(&mut node.modem.shared().host_out);
            if !node.down && !said.is_empty() {
                moved = true;
                node.inputs.push_back(Input::Read(said.concat()));
            }
            let sent = std::mem::take(&mut node.modem.shared().water_out);
            for mt in sent {
                moved = true;
                self.in_flight.push((self.now.at + self.travel, 1 - i, mt));
            }
        }
        moved
    }

    fn outputs(&mut self, i: usize, outputs: Vec<Output>) {
        let now = self.now.at;
        let node = &mut self.nodes[i];
        for output in outputs {
            match output {
                // The drivers of these modems read and write bytes.
                Output::Write(bytes) if !node.down => node.modem.host(&bytes, now),
                Output::Write(_) | Output::Keep(_) => {}
                Output::Event(event) => node.events.push(event),
                Output::Request { id, mut template } => {
                    template.frame = node
                        .frames
                        .iter()
                        .take(template.max_num_frames().max(1) as usize)
                        .cloned()
                        .collect();
                    node.inputs.push_back(Input::Answer {
                        id,
                        filled: Some(template),
                    });
                }
                Output::Open => {
                    node.down = false;
                    node.modem.connected();
                    node.inputs.push_back(Input::Opened(true));
                }
            }
        }
    }
}

/// Whether `events` hold `status`.
pub fn told(events: &[DriverEvent], status: impl Fn(&DriverStatus) -> bool) -> bool {
    events
        .iter()
        .any(|e| matches!(e, DriverEvent::Status(s) if status(s)))
}

/// The transmissions received among `events`.
pub fn received(events: &[DriverEvent]) -> Vec<&ModemTransmission> {
    events
        .iter()
        .filter_map(|e| match e {
            DriverEvent::Received(mt) => Some(mt),
            _ => None,
        })
        .collect()
}
