//! `ACOMMS_MAC_SWITCH` through `gobyd`'s MOOS interface against the
//! minimal in-process DB: a switch with a keep-alive, the same value again
//! renewing it, an unknown MAC refused, a value that does not read never
//! reaching the core; each told on the `mac` events from `moos`, and the
//! running MAC written to `ACOMMS_MAC_ACTIVE`.

mod support;

use std::time::Duration;

use gobyd::event::{DaemonEvent, ModemEvent};
use support::daemon::scratch;
use support::moosdb::{mini_db_with_client, start_on_moos};
use support::node::{Node, Simulator};

const PATIENCE: Duration = Duration::from_secs(20);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mac_switch_switches_renews_and_refuses_as_told() {
    let dir = scratch("moos-mac-switch", "switch");
    let (db, client, mut mail) = mini_db_with_client("macswitch", "ACOMMS_MAC_SLOT_START").await;
    let config = Node::new(1)
        .driver(Simulator::alone().overhead(0.05))
        .json_tcp("")
        .data_dir(&dir.join("data"))
        .moos(db.port(), r#"name: "gobyd1""#)
        .extra("moos_var {}")
        .mac_switcher("survey", &[("survey", 6, 1.0), ("quiet", 6, 2.0)])
        .config();
    // gobyd is connected once its slot starts come.
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let mut gobyd = start_on_moos(config, &mut mail, deadline).await;
    client
        .register("ACOMMS_MAC_ACTIVE", Duration::ZERO)
        .unwrap();
    for value in [
        "mac=quiet,keep_alive=600",
        "keep_alive=600,mac=quiet",
        "mac=quiet,keep_alive=soon",
        "loud",
    ] {
        client.notify_string("ACOMMS_MAC_SWITCH", value).unwrap();
    }
    let mut told = Vec::new();
    while told.len() < 3 {
        let e = tokio::time::timeout_at(deadline, gobyd.events.recv())
            .await
            .expect("the switches are told")
            .unwrap();
        if let DaemonEvent::Modem {
            event: ModemEvent::MacSwitch(s),
            ..
        } = e.as_ref()
        {
            assert_eq!(s.from, Some("moos"), "{s:?}");
            told.push((
                s.active.clone(),
                s.reason,
                s.until.is_some(),
                s.error.clone(),
            ));
        }
    }
    assert_eq!(told[0], ("quiet".into(), "requested", true, None));
    assert_eq!(told[1], ("quiet".into(), "renewed", true, None));
    assert_eq!((told[2].0.as_str(), told[2].1), ("quiet", "refused"));
    assert!(
        told[2].3.as_deref().unwrap().contains("\"loud\""),
        "{told:?}"
    );
    // The running MAC is written on connecting (the database hands it over
    // on registration), then at each switch or renewal, not at a refusal.
    let mut active = Vec::new();
    while active.len() < 3 {
        let m = tokio::time::timeout_at(deadline, mail.recv())
            .await
            .expect("MAC_ACTIVE is written")
            .unwrap();
        if let ("ACOMMS_MAC_ACTIVE", moos::Value::String(value)) = (m.key.as_str(), m.value) {
            active.push(value);
        }
    }
    assert_eq!(active[0], "mac=survey,reason=started");
    for (value, reason) in active[1..].iter().zip(["requested", "renewed"]) {
        let head = format!("mac=quiet,reason={reason},keep_alive_until=");
        let until: f64 = value
            .strip_prefix(&head)
            .unwrap_or_else(|| panic!("{value:?} starts {head:?}"))
            .parse()
            .unwrap();
        assert!(until > 1.7e9, "{value}");
    }
    gobyd.stop().await;
    client.close().await;
    let _ = std::fs::remove_dir_all(&dir);
}
