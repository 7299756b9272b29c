//! Helpers shared by the driver tests.
#![allow(dead_code)]

use std::time::Duration;

use modemdriver::{Driver, DriverEvent, ModemTransmission};

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
