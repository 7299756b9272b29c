//! The rate chosen from the link, in virtual time: node 1's slot to node 2
//! has `adaptive_rate`; its driver (a stand-in Micro-Modem that reports
//! the `$CACST` SNR of each reception from node 2) is handed the slot's
//! own rate while nothing is heard, rate 5 once node 2 is heard at 20 dB,
//! rate 3 when the SNR falls to 3 dB; each choice and its reason are on
//! the `mac` events.

mod support;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use gobyd::daemon::Daemon;
use gobyd::event::{DaemonEvent, ModemEvent};
use modemdriver::time::TokioClock;
use modemdriver::{Driver, DriverCommand, DriverEvent, ModemTransmission};
use protos::goby::acomms::protobuf::MicroModemReceiveStatistics;
use support::daemon::scratch;
use support::node::{Node, Simulator};
use tokio::sync::{mpsc, oneshot};

/// A driver that reports the receptions it is given and keeps the rate
/// of every transmission it is asked to initiate.
fn stand_in(
    clock: Arc<TokioClock>,
    rates: Arc<Mutex<Vec<i32>>>,
    mut heard: mpsc::UnboundedReceiver<ModemTransmission>,
) -> Driver {
    Driver::spawn_with_clock("stand-in", clock, move |mut ctx| async move {
        loop {
            tokio::select! {
                command = ctx.commands.recv() => match command {
                    Some(DriverCommand::Initiate(t)) => rates.lock().unwrap().push(t.rate()),
                    Some(DriverCommand::Stop(done)) => {
                        let _ = done.send(());
                        return;
                    }
                    Some(_) => {}
                    None => return,
                },
                Some(t) = heard.recv() => ctx.events.emit(DriverEvent::Received(t)),
            }
        }
    })
}

/// A reception from node 2 with the modem's SNR (`snr_in`, dB).
fn from_two(snr: i32) -> ModemTransmission {
    ModemTransmission {
        src: Some(2),
        dest: Some(1),
        rate: Some(1),
        receive_stat: vec![MicroModemReceiveStatistics {
            source: Some(2),
            snr_in: Some(snr),
            ..Default::default()
        }],
        ..Default::default()
    }
}

#[tokio::test(start_paused = true)]
async fn the_rate_follows_the_snr_heard_and_each_choice_is_told() {
    let dir = scratch("adaptive-rate", "snr");
    let clock = Arc::new(TokioClock::new());
    let config = Node::new(1)
        .driver(Simulator::pair(500.0))
        .json_tcp("")
        .data_dir(&dir)
        .extra(
            "mac { type: MAC_FIXED_DECENTRALIZED \
             slot { src: 1 dest: 2 rate: 1 slot_seconds: 10 adaptive_rate: true } \
             slot { src: 2 dest: 1 rate: 1 slot_seconds: 10 } }",
        )
        .config();
    let rates: Arc<Mutex<Vec<i32>>> = Arc::default();
    let (hear, heard) = mpsc::unbounded_channel();
    let daemon = Daemon::builder(config)
        .driver(stand_in(clock.clone(), rates.clone(), heard))
        .clock(clock.clone())
        .start()
        .await
        .expect("gobyd starts");
    let mut events = daemon.subscribe();
    let (stop, stopped) = oneshot::channel::<()>();
    let run = tokio::spawn(daemon.run(async move {
        let _ = stopped.await;
    }));
    let mut told = Vec::new();
    let follow = |snr: Option<i32>| {
        if let Some(snr) = snr {
            for _ in 0..5 {
                hear.send(from_two(snr)).unwrap();
            }
        }
    };
    let watch = async |events: &mut tokio::sync::broadcast::Receiver<_>| {
        let until = tokio::time::Instant::now() + Duration::from_secs(40);
        let mut seen = Vec::new();
        while let Ok(event) = tokio::time::timeout_at(until, events.recv()).await {
            let Ok(event) = event else { continue };
            let event: Arc<DaemonEvent> = event;
            match &*event {
                DaemonEvent::Modem {
                    event: ModemEvent::RateChoice { dest, choice, .. },
                    ..
                } => seen.push((*dest, choice.rate, choice.reason.name())),
                // The slot start tells the rate chosen.
                DaemonEvent::Modem {
                    event:
                        ModemEvent::SlotStart {
                            initiated: Some(t), ..
                        },
                    ..
                } => assert_eq!(Some(t.rate()), seen.last().map(|s| s.1)),
                _ => {}
            }
        }
        seen
    };
    follow(None);
    told.extend(watch(&mut events).await);
    follow(Some(20));
    told.extend(watch(&mut events).await);
    follow(Some(3));
    told.extend(watch(&mut events).await);
    let _ = stop.send(());
    run.await.unwrap().unwrap();

    let mut changes: Vec<(i32, i32, &str)> = told.clone();
    changes.dedup_by(|a, b| a.1 == b.1);
    assert_eq!(
        changes,
        [(2, 1, "no_link_data"), (2, 5, "up"), (2, 3, "down")],
        "{told:?}"
    );
    // What the driver was handed is what was told.
    let handed = rates.lock().unwrap().clone();
    let chosen: Vec<i32> = told.iter().map(|t| t.1).collect();
    assert_eq!(handed, chosen);
}
