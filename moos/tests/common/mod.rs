//! Scenarios shared by the tests against the minimal DB and against a real MOOSDB.

#![allow(dead_code)]

use std::time::Duration;

use moos::{ClientConfig, ConnectionState, Mail, MailReceiver, MoosClient, Value};
use tokio::time::timeout;

/// Upper bound for any single wait in these tests.
pub const LIMIT: Duration = Duration::from_secs(10);

/// A client configuration with short periods, for a DB on 127.0.0.1:`port`.
pub fn config(name: &str, port: u16) -> ClientConfig {
    let mut c = ClientConfig::new(name).with_address("127.0.0.1", port);
    c.heartbeat_period = Duration::from_millis(200);
    c.silence_timeout = Duration::from_secs(2);
    c.reconnect_delay = Duration::from_millis(100);
    c.connect_timeout = Duration::from_secs(2);
    c
}

/// Connects with a bounded wait.
pub async fn connect(name: &str, port: u16) -> (MoosClient, MailReceiver) {
    timeout(LIMIT, MoosClient::connect(config(name, port)))
        .await
        .expect("connect timed out")
        .unwrap_or_else(|e| panic!("{name} cannot connect: {e}"))
}

/// The next mail for `key`, skipping others; panics after [`LIMIT`].
pub async fn mail_for(rx: &mut MailReceiver, key: &str) -> Mail {
    timeout(LIMIT, async {
        loop {
            let mail = rx.recv().await.expect("mail channel closed");
            if mail.key == key {
                return mail;
            }
        }
    })
    .await
    .unwrap_or_else(|_| panic!("no mail for {key} within {LIMIT:?}"))
}

/// Registers `vars` and waits until the DB has processed the registrations: the client
/// writes a probe variable it registered last and waits for it to come back.
pub async fn register_and_sync(client: &MoosClient, rx: &mut MailReceiver, vars: &[&str]) {
    for var in vars {
        client.register(var, Duration::ZERO).unwrap();
    }
    let probe = format!("{}_PROBE", client.name().to_uppercase());
    client.register(&probe, Duration::ZERO).unwrap();
    client.notify_string(&probe, "sync").unwrap();
    mail_for(rx, &probe).await;
}

/// Waits until the client's session counter reaches `session`.
pub async fn wait_for_session(client: &MoosClient, session: u64) {
    let mut state = client.state();
    timeout(
        LIMIT,
        state.wait_for(
            |s| matches!(s, ConnectionState::Connected { session: n, .. } if *n >= session),
        ),
    )
    .await
    .unwrap_or_else(|_| {
        panic!(
            "{} not in session {session} within {LIMIT:?}",
            client.name()
        )
    })
    .expect("client gone");
}

/// Waits until the client notices it lost the connection.
pub async fn wait_for_disconnect(client: &MoosClient) {
    let mut state = client.state();
    timeout(LIMIT, state.wait_for(|s| *s == ConnectionState::Connecting))
        .await
        .unwrap_or_else(|_| panic!("{} did not notice the DB going away", client.name()))
        .expect("client gone");
}

/// Two clients: `a` subscribes, `b` publishes a string, a double and bytes, `a` gets
/// each with `b` as the source.
pub async fn round_trip(port: u16, prefix: &str) -> (MoosClient, MailReceiver, MoosClient) {
    let (a, mut a_mail) = connect(&format!("{prefix}_a"), port).await;
    let (b, _b_mail) = connect(&format!("{prefix}_b"), port).await;
    register_and_sync(&a, &mut a_mail, &["GOBY_OUT", "GOBY_DEPTH", "GOBY_RAW"]).await;

    b.notify_string("GOBY_OUT", "hello from b").unwrap();
    let mail = mail_for(&mut a_mail, "GOBY_OUT").await;
    assert_eq!(mail.value, Value::String("hello from b".into()));
    assert_eq!(mail.source, b.name());
    assert!(mail.time > 1.0e9, "time stamp {}", mail.time);

    b.notify_double("GOBY_DEPTH", 12.5).unwrap();
    assert_eq!(
        mail_for(&mut a_mail, "GOBY_DEPTH").await.value,
        Value::Double(12.5)
    );

    b.notify_binary("GOBY_RAW", &[0, 1, 0xfe, 0xff]).unwrap();
    assert_eq!(
        mail_for(&mut a_mail, "GOBY_RAW").await.value,
        Value::Binary(vec![0, 1, 0xfe, 0xff])
    );
    (a, a_mail, b)
}
