//! One conformance suite for every modem driver and its emulated modem:
//! start-up, send, receive, ack, garbage, disconnect and busy, the same
//! checks for each kind ([`kinds`]).
//!
//! The driver's logic runs in virtual time, sans I/O ([`water`]): its
//! machine and the emulated modem coupled directly, time jumping to the
//! next deadline (an hour of retries costs nothing, and a run repeats
//! exactly). The device is under test once per kind ([`device`]): two
//! drivers started from their configurations on real TCP connections and
//! pseudo-terminals to two emulated modems on the acoustic channel
//! simulator, their connection dropped and made again. What one modem
//! does and the others do not is in [`extras`].
//!
//! `cargo nextest run -p goby-modemdriver --test conformance`

mod device;
mod extras;
mod kinds;
mod water;

use std::time::Duration;

use emulators::host::EmulatorControl;
use modemdriver::machine::Now;
use modemdriver::{DriverCommand, DriverEvent, DriverStatus, ModemTransmission, TransmitOutcome};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use tokio::time::Instant;

use kinds::{Kind, Reach};
use water::{received, told, Water};

/// Longest a check waits, in virtual time.
const PATIENCE: Duration = Duration::from_secs(120);

/// Two nodes of `kind` (modem ids 1 and 2) on virtual water.
fn pair(kind: &Kind) -> Water {
    let now = Now {
        at: Instant::now(),
        micros: 1_700_000_000_000_000,
    };
    // The interface each emulated modem takes unless told otherwise: TCP
    // (data mode, the JSON port) or its serial line.
    let reach = match kind.emulation().host {
        emulators::kinds::Host::Tcp(port) => Reach::Tcp(([127, 0, 0, 1], port).into()),
        emulators::kinds::Host::Serial => Reach::Serial("/dev/null".into()),
    };
    let node = |id: u8| {
        let config = (kind.config)(i32::from(id), &reach);
        ((kind.machine)(&config, now), (kind.modem)(id))
    };
    let travel = Duration::from_secs_f64(kinds::SPACING / 1500.0);
    Water::new(now, [node(1), node(2)], travel)
}

/// Both drivers ready.
fn ready(kind: &Kind) -> Water {
    let mut w = pair(kind);
    let up = w.run_until(PATIENCE, |n| {
        n.iter()
            .all(|n| told(&n.events, |s| *s == DriverStatus::Ready))
    });
    assert!(up, "{}: both drivers ready", kind.name);
    for n in &mut w.nodes {
        n.events.clear();
    }
    w
}

/// Data of `frame` from node `from` (modem id `from + 1`) to `dest` at
/// the kind's rate, `ack` asked for, `unique_id` 42.
fn send(w: &mut Water, kind: &Kind, from: usize, dest: i32, frame: &[u8], ack: bool) {
    w.nodes[from].frames = vec![frame.to_vec()];
    w.command(
        from,
        DriverCommand::Initiate(ModemTransmission {
            dest: Some(dest),
            rate: Some(kind.rate),
            unique_id: Some(42),
            ack_requested: Some(ack),
            r#type: Some(TransmissionType::Data as i32),
            ..Default::default()
        }),
    );
}

/// The data heard by node `at`, once there is some.
fn heard(w: &mut Water, at: usize) -> Option<ModemTransmission> {
    w.run_until(PATIENCE, |n| {
        received(&n[at].events)
            .iter()
            .any(|t| t.r#type() == TransmissionType::Data)
    });
    received(&w.nodes[at].events)
        .into_iter()
        .find(|t| t.r#type() == TransmissionType::Data)
        .cloned()
}

/// The ack heard by node `at`, once there is one.
fn acked(w: &mut Water, at: usize) -> Option<ModemTransmission> {
    w.run_until(PATIENCE, |n| {
        received(&n[at].events)
            .iter()
            .any(|t| t.r#type() == TransmissionType::Ack)
    });
    received(&w.nodes[at].events)
        .into_iter()
        .find(|t| t.r#type() == TransmissionType::Ack)
        .cloned()
}

/// The outcome of node `at`'s transmission, once told.
fn outcome(w: &mut Water, at: usize) -> Option<TransmitOutcome> {
    let result = |events: &[DriverEvent]| {
        events.iter().find_map(|e| match e {
            DriverEvent::TransmitResult(r) => Some(r.outcome.clone()),
            _ => None,
        })
    };
    w.run_until(PATIENCE, |n| result(&n[at].events).is_some());
    result(&w.nodes[at].events)
}

/// Node `from` sends `frame` to the other with an ack: the other hears it
/// whole, from one to the other, with the modem's statistics; `from` is
/// told it was sent and hears the ack of frame 0, naming the
/// transmission.
fn exchange_from(w: &mut Water, kind: &Kind, from: usize, frame: &[u8]) {
    let (src, dest) = (from as i32 + 1, 2 - from as i32);
    let to = 1 - from;
    for n in &mut w.nodes {
        n.events.clear();
    }
    send(w, kind, from, dest, frame, true);
    let got = heard(w, to).unwrap_or_else(|| panic!("{}: no data heard", kind.name));
    assert_eq!((got.src(), got.dest()), (src, dest), "{}", kind.name);
    assert_eq!(got.frame, vec![frame.to_vec()], "{}", kind.name);
    assert!((kind.stats)(&got), "{}: statistics: {got:?}", kind.name);
    assert_eq!(
        outcome(w, from),
        Some(TransmitOutcome::Sent),
        "{}",
        kind.name
    );
    let ack = acked(w, from).unwrap_or_else(|| panic!("{}: no ack heard", kind.name));
    assert_eq!((ack.src(), ack.dest()), (dest, src), "{}", kind.name);
    assert_eq!(ack.acked_frame, vec![0], "{}", kind.name);
    assert_eq!(ack.unique_id, Some(42), "{}", kind.name);
}

/// Node 0 (modem 1) sends `frame` to modem 2 ([`exchange_from`]).
fn exchange(w: &mut Water, kind: &Kind, frame: &[u8]) {
    exchange_from(w, kind, 0, frame);
}

/// Start-up: each driver sets its modem up and says it is ready.
fn start_up(kind: &Kind) {
    ready(kind);
}

/// Send, receive and ack, each way.
fn send_receive_ack(kind: &Kind) {
    let mut w = ready(kind);
    exchange_from(&mut w, kind, 0, b"one to two");
    exchange_from(&mut w, kind, 1, b"two to one");
}

/// A broadcast is heard by every node, asks for no ack and gets none.
fn broadcast(kind: &Kind) {
    let mut w = ready(kind);
    send(&mut w, kind, 0, 0, b"everyone", true);
    let got = heard(&mut w, 1).expect("the broadcast heard");
    assert_eq!((got.src(), got.dest()), (1, 0), "{}", kind.name);
    assert!(!got.ack_requested(), "{}", kind.name);
    w.run_until(Duration::from_secs(30), |_| false);
    assert!(
        acked(&mut w, 0).is_none(),
        "{}: no ack of a broadcast",
        kind.name
    );
}

/// Garbage from the modem (a line garbled on its way) is reported and
/// survived: the next data goes and is acked.
fn garbage(kind: &Kind) {
    let mut w = ready(kind);
    w.control(1, EmulatorControl::Garble(1));
    send(&mut w, kind, 0, 2, b"maybe lost", true);
    let reported = w.run_until(PATIENCE, |n| {
        told(&n[1].events, |s| {
            matches!(
                s,
                DriverStatus::Unparseable { .. } | DriverStatus::BadChecksum { .. }
            )
        })
    });
    assert!(reported, "{}: the garbled line told", kind.name);
    w.run_until(Duration::from_secs(30), |_| false);
    exchange(&mut w, kind, b"after the garbage");
}

/// The link to the modem drops: the driver says so, opens it again, sets
/// the modem up and goes on.
fn disconnect(kind: &Kind) {
    let mut w = ready(kind);
    w.drop_link(0);
    let back = w.run_until(PATIENCE, |n| {
        told(&n[0].events, |s| {
            matches!(s, DriverStatus::Disconnected { .. })
        }) && told(&n[0].events, |s| *s == DriverStatus::Reconnected)
            && told(&n[0].events, |s| *s == DriverStatus::Ready)
    });
    assert!(back, "{}: disconnected, reconnected, ready", kind.name);
    exchange(&mut w, kind, b"after the drop");
}

/// The modem refuses the first send: the driver offers it again, and it
/// goes and is acked.
fn busy(kind: &Kind) {
    let mut w = ready(kind);
    w.control(0, EmulatorControl::Busy(1));
    exchange(&mut w, kind, b"after busy");
    let retries = w.nodes[0]
        .events
        .iter()
        .filter(|e| matches!(e, DriverEvent::Status(DriverStatus::Retrying { .. })))
        .count();
    assert_eq!(
        retries, 1,
        "{}: the one refusal told, the send tried again",
        kind.name
    );
}

/// The suite for each kind, one test a check.
macro_rules! suite {
    ($($module:ident: $kind:path),* $(,)?) => {$(
        mod $module {
            #[test]
            fn start_up() {
                super::start_up(&$kind)
            }
            #[test]
            fn send_receive_ack() {
                super::send_receive_ack(&$kind)
            }
            #[test]
            fn broadcast() {
                super::broadcast(&$kind)
            }
            #[test]
            fn garbage() {
                super::garbage(&$kind)
            }
            #[test]
            fn disconnect() {
                super::disconnect(&$kind)
            }
            #[test]
            fn busy() {
                super::busy(&$kind)
            }
            #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
            async fn on_the_device() {
                super::device::on_the_device(&$kind).await
            }
        }
    )*};
}

suite! {
    evologics: crate::kinds::EVOLOGICS,
    popoto: crate::kinds::POPOTO,
    benthos: crate::kinds::BENTHOS,
    seatrac: crate::kinds::SEATRAC,
}
