//! The device under test: two drivers started from their configurations
//! (`modemdriver::built_in::start`) on two emulated modems started from
//! the emulators' table (`emulators::kinds`), their packets on the
//! acoustic channel simulator. Modem 1 serves its host on TCP, modem 2 on
//! a pseudo-terminal (or, for a modem on a serial line, the other way
//! round: modem 1 on its pseudo-terminal, modem 2 through a serial server
//! on TCP). Both start up; data goes each way with its ack; the TCP
//! connection drops and the driver connects again and goes on.

use std::time::Duration;

use emulators::host::{EmulatorControl, EmulatorFaults, EmulatorPort, Running, Setup};
use emulators::kinds::Host;
use modemdriver::sim::{medium::Medium, SimulatorDriver};
use modemdriver::TransmitOutcome;
use modemdriver::{Driver, DriverConfig, DriverEvent, DriverStatus, ModemTransmission};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::simulator_driver_config::NodePosition;
use protos::goby::acomms::protobuf::SimulatorDriverConfig;

use super::kinds::{positions, Kind, Reach, SPACING};

/// Longest a step waits.
const LIMIT: Duration = Duration::from_secs(30);

/// Reads `driver`'s events until `pick` finds one, answering data
/// requests with `frames`.
async fn wait_for<T>(
    driver: &mut Driver,
    frames: &[Vec<u8>],
    mut pick: impl FnMut(&DriverEvent) -> Option<T>,
) -> T {
    let found = tokio::time::timeout(LIMIT, async {
        loop {
            let event = driver.next_event().await.expect("driver running");
            if let Some(t) = pick(&event) {
                return t;
            }
            if let DriverEvent::DataRequest(request) = event {
                let mut filled = request.template().clone();
                filled.frame = frames.to_vec();
                request.respond(filled);
            }
        }
    })
    .await;
    found.unwrap_or_else(|_| panic!("no expected event from {} within {LIMIT:?}", driver.name()))
}

async fn ready(driver: &mut Driver) {
    wait_for(driver, &[], |e| {
        matches!(e, DriverEvent::Status(DriverStatus::Ready)).then_some(())
    })
    .await
}

/// `frame` from `from` (modem `src`) to modem `dest`, acked.
async fn exchange(from: &mut Driver, to: &mut Driver, dest: i32, frame: &[u8]) {
    from.initiate_transmission(ModemTransmission {
        dest: Some(dest),
        unique_id: Some(42),
        ack_requested: Some(true),
        r#type: Some(TransmissionType::Data as i32),
        ..Default::default()
    })
    .unwrap();
    let frames = [frame.to_vec()];
    let sent = wait_for(from, &frames, |e| match e {
        DriverEvent::TransmitResult(r) => Some(r.clone()),
        _ => None,
    })
    .await;
    assert_eq!(sent.outcome, TransmitOutcome::Sent, "{sent:?}");
    let got = wait_for(to, &[], |e| match e {
        DriverEvent::Received(t) if t.r#type() == TransmissionType::Data => Some(t.clone()),
        _ => None,
    })
    .await;
    assert_eq!(got.frame, frames);
    assert_eq!(got.dest(), dest);
    let ack = wait_for(from, &[], |e| match e {
        DriverEvent::Received(t) if t.r#type() == TransmissionType::Ack => Some(t.clone()),
        _ => None,
    })
    .await;
    assert_eq!((ack.src(), ack.unique_id), (dest, Some(42)));
}

/// The simulator's node of modem `id`, on `medium`.
fn backend(id: u8, medium: &std::sync::Arc<Medium>) -> Driver {
    let node = (1..=2)
        .map(|m: i32| NodePosition {
            modem_id: m,
            x: Some(f64::from(m - 1) * SPACING),
            ..Default::default()
        })
        .collect();
    let config = DriverConfig {
        modem_id: Some(i32::from(id)),
        simulator: Some(SimulatorDriverConfig {
            node,
            packet_overhead_seconds: Some(0.1),
            ..Default::default()
        }),
        ..Default::default()
    };
    SimulatorDriver::start_on(&config, medium.clone()).expect("the simulator starts")
}

/// Emulated modems 1 and 2 of `kind`, one on TCP (the one that drops),
/// one on a pseudo-terminal under `dir`; and where each is reached.
async fn modems(kind: &Kind, dir: &std::path::Path) -> (Vec<Running>, Vec<Reach>, usize) {
    let emulation = kind.emulation();
    // The modem on TCP: 1 for a modem with an Ethernet interface, 2 for
    // one on a serial line (then through a serial server).
    let on_tcp = match emulation.host {
        Host::Tcp(_) => 0,
        Host::Serial => 1,
    };
    let medium = Medium::new();
    let (mut running, mut reach) = (Vec::new(), Vec::new());
    for (i, id) in [1u8, 2].into_iter().enumerate() {
        let port = if i == on_tcp {
            EmulatorPort::Tcp("127.0.0.1:0".parse().unwrap())
        } else {
            EmulatorPort::Pty {
                link: Some(dir.join(format!("{}-{id}", kind.name))),
            }
        };
        let setup = Setup {
            address: id,
            positions: positions(),
            faults: EmulatorFaults::default(),
            usbl: false,
        };
        let modem = (emulation.start)(setup, port, Some(backend(id, &medium)))
            .await
            .expect("the emulator starts");
        let shown = modem.shown();
        reach.push(match shown.strip_prefix("tcp ") {
            Some(addr) => Reach::Tcp(addr.parse().unwrap()),
            None => Reach::Serial(shown),
        });
        running.push(modem);
    }
    (running, reach, on_tcp)
}

pub async fn on_the_device(kind: &Kind) {
    let dir = std::env::temp_dir().join(format!(
        "goby-conformance-{}-{}",
        kind.name,
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let (modems, reach, on_tcp) = modems(kind, &dir).await;
    let mut drivers = Vec::new();
    for (i, r) in reach.iter().enumerate() {
        let config = (kind.config)(i as i32 + 1, r);
        drivers.push(modemdriver::built_in::start(&config).await.expect("starts"));
    }
    let [one, two] = &mut drivers[..] else {
        unreachable!()
    };
    ready(one).await;
    ready(two).await;
    exchange(one, two, 2, b"one to two").await;
    exchange(two, one, 1, b"two to one").await;

    // The TCP connection dropped: the driver says so, connects again,
    // sets its modem up and goes on.
    modems[on_tcp].control(EmulatorControl::DropConnection);
    let dropped = if on_tcp == 0 { &mut *one } else { &mut *two };
    wait_for(dropped, &[], |e| {
        matches!(e, DriverEvent::Status(DriverStatus::Disconnected { .. })).then_some(())
    })
    .await;
    ready(dropped).await;
    exchange(one, two, 2, b"after the drop").await;
    assert_eq!(
        modems[on_tcp].connections(),
        2,
        "{}: connected again",
        kind.name
    );

    for d in drivers {
        d.stop().await.unwrap();
    }
    for m in modems {
        m.stop().await;
    }
    let _ = std::fs::remove_dir_all(&dir);
}
