//! Helpers shared by the driver tests.
#![allow(dead_code)]

use std::time::Duration;

use modemdriver::{Driver, DriverEvent, ModemTransmission, TransmitOutcome, TransmitResult};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;

/// Reads events until `pick` returns something, answering data requests with
/// `frames` (as many as the template allows). Panics after `limit`.
pub async fn wait_for<T>(
    driver: &mut Driver,
    frames: &[Vec<u8>],
    limit: Duration,
    mut pick: impl FnMut(&DriverEvent) -> Option<T>,
) -> T {
    let found = tokio::time::timeout(limit, async {
        loop {
            let event = driver.next_event().await.expect("driver running");
            if let Some(t) = pick(&event) {
                return t;
            }
            if let DriverEvent::DataRequest(request) = event {
                let mut filled = request.template().clone();
                filled.frame = frames
                    .iter()
                    .take(filled.max_num_frames() as usize)
                    .cloned()
                    .collect();
                request.respond(filled);
            }
        }
    })
    .await;
    found.unwrap_or_else(|_| {
        panic!(
            "no expected event from the {} driver within {limit:?}",
            driver.name()
        )
    })
}

/// Data with an ack asked for from `a` (modem id 1) to `b` (modem id 2)
/// between two drivers that ack in software: `a` sends `frames`, `b` hears
/// them, `a` hears the ack of frame 0. Returns what `a` sent.
pub async fn data_and_ack(
    a: &mut Driver,
    b: &mut Driver,
    frames: &[Vec<u8>],
    limit: Duration,
) -> TransmitResult {
    a.initiate_transmission(ModemTransmission {
        dest: Some(2),
        ack_requested: Some(true),
        r#type: Some(TransmissionType::Data as i32),
        ..Default::default()
    })
    .unwrap();
    let sent = wait_for(a, frames, limit, |e| match e {
        DriverEvent::TransmitResult(r) => Some(r.clone()),
        _ => None,
    })
    .await;
    assert_eq!(sent.outcome, TransmitOutcome::Sent);
    assert_eq!(sent.transmission.src(), 1);

    let got = received(b, limit).await;
    assert_eq!((got.src(), got.dest()), (1, 2));
    assert_eq!(got.frame, frames);
    assert_eq!(got.r#type(), TransmissionType::Data);

    let ack = received(a, limit).await;
    assert_eq!(ack.r#type(), TransmissionType::Ack);
    assert_eq!((ack.src(), ack.dest()), (2, 1));
    assert_eq!(ack.acked_frame, vec![0]);
    assert_eq!(ack.unique_id, sent.transmission.unique_id);
    sent
}

/// The next received transmission.
pub async fn received(driver: &mut Driver, limit: Duration) -> ModemTransmission {
    wait_for(driver, &[], limit, |e| match e {
        DriverEvent::Received(mt) => Some(mt.clone()),
        _ => None,
    })
    .await
}

/// Every received transmission until `limit` passes (answering data
/// requests with `frames`).
pub async fn collect_received(
    driver: &mut Driver,
    frames: &[Vec<u8>],
    limit: Duration,
) -> Vec<ModemTransmission> {
    let mut out = Vec::new();
    let deadline = tokio::time::Instant::now() + limit;
    while let Ok(Some(event)) = tokio::time::timeout_at(deadline, driver.next_event()).await {
        match event {
            DriverEvent::Received(mt) => out.push(mt),
            DriverEvent::DataRequest(request) => {
                let mut filled = request.template().clone();
                filled.frame = frames.to_vec();
                request.respond(filled);
            }
            _ => {}
        }
    }
    out
}
