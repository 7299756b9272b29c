//! The client against the in-process minimal DB, over real TCP on 127.0.0.1.

mod common;

use std::time::Duration;

use common::{
    config, connect, mail_for, register_and_sync, round_trip, wait_for_disconnect,
    wait_for_session, LIMIT,
};
use moos::testing::MiniDb;
use moos::wire::{self, Message, MessageKind, PROTOCOL_PREAMBLE_LEN};
use moos::{ClientError, ConnectionState, MoosClient, Value};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpListener;
use tokio::time::{sleep, timeout};

async fn mini_db() -> MiniDb {
    MiniDb::start("127.0.0.1:0", "gobytest").await.unwrap()
}

#[tokio::test]
async fn handshake_reports_the_community() {
    let db = mini_db().await;
    let (a, _mail) = connect("handshake", db.port()).await;
    assert!(a.is_connected());
    assert_eq!(
        *a.state().borrow(),
        ConnectionState::Connected {
            community: "gobytest".into(),
            session: 1
        }
    );
    assert_eq!(db.clients(), vec!["handshake".to_string()]);
    a.close().await;
    db.stop().await;
}

#[tokio::test]
async fn notifications_reach_a_subscribed_client() {
    let db = mini_db().await;
    let (a, _a_mail, b) = round_trip(db.port(), "rt").await;
    assert_eq!(db.value("GOBY_DEPTH"), Some(Value::Double(12.5)));
    a.close().await;
    b.close().await;
    db.stop().await;
}

#[tokio::test]
async fn late_registration_gets_the_current_value_and_unregister_stops_mail() {
    let db = mini_db().await;
    let (b, _b_mail) = connect("late_b", db.port()).await;
    let (a, mut a_mail) = connect("late_a", db.port()).await;
    b.notify_string("EARLY", "first").unwrap();
    // b's notification is processed before a's later registration only if b sent first;
    // wait until the DB has it.
    timeout(LIMIT, async {
        while db.value("EARLY").is_none() {
            sleep(Duration::from_millis(10)).await;
        }
    })
    .await
    .unwrap();
    a.register("EARLY", Duration::ZERO).unwrap();
    assert_eq!(
        mail_for(&mut a_mail, "EARLY").await.value,
        Value::String("first".into())
    );

    a.unregister("EARLY").unwrap();
    register_and_sync(&a, &mut a_mail, &[]).await;
    b.notify_string("EARLY", "second").unwrap();
    b.notify_string("LATE_A_PROBE", "after").unwrap();
    // The probe comes after "second" from the same sender: if "EARLY" were still
    // subscribed it would arrive first.
    let next = timeout(LIMIT, a_mail.recv()).await.unwrap().unwrap();
    assert_eq!(next.key, "LATE_A_PROBE");
    assert_eq!(next.value, Value::String("after".into()));
    assert!(a_mail.try_recv().is_err(), "no more mail expected");
    db.stop().await;
}

#[tokio::test]
async fn a_registration_right_after_connecting_is_made_once() {
    let db = mini_db().await;
    let (b, _b_mail) = connect("once_b", db.port()).await;
    b.notify_double("ONCE", 1.0).unwrap();
    timeout(LIMIT, async {
        while db.value("ONCE").is_none() {
            sleep(Duration::from_millis(10)).await;
        }
    })
    .await
    .unwrap();
    // Registered before the client's task has sent anything: the DB sees
    // one registration, so the current value comes once.
    let (a, mut a_mail) = connect("once_a", db.port()).await;
    a.register("ONCE", Duration::ZERO).unwrap();
    a.register("ONCE_PROBE", Duration::ZERO).unwrap();
    a.notify_string("ONCE_PROBE", "sync").unwrap();
    // Everything up to the probe's return: the DB answered every
    // registration before it.
    let mut keys = Vec::new();
    timeout(LIMIT, async {
        loop {
            let mail = a_mail.recv().await.unwrap();
            if mail.key == "ONCE_PROBE" {
                break;
            }
            keys.push((mail.key, mail.value));
        }
    })
    .await
    .unwrap();
    assert_eq!(keys, [("ONCE".to_string(), Value::Double(1.0))]);
    db.stop().await;
}

#[tokio::test]
async fn a_second_client_of_the_same_name_is_refused() {
    let db = mini_db().await;
    let (_a, _mail) = connect("twin", db.port()).await;
    let err = MoosClient::connect(config("twin", db.port()))
        .await
        .unwrap_err();
    match &err {
        ClientError::Refused { name, reason, .. } => {
            assert_eq!(name, "twin");
            assert!(reason.contains("already exists"), "{reason}");
        }
        other => panic!("expected Refused, got {other}"),
    }
    db.stop().await;
}

#[tokio::test]
async fn nothing_listening_is_a_connect_error() {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    drop(listener);
    let err = MoosClient::connect(config("lonely", port))
        .await
        .unwrap_err();
    assert!(matches!(err, ClientError::Connect { .. }), "{err}");
    assert!(
        err.to_string().contains(&format!("127.0.0.1:{port}")),
        "{err}"
    );
}

#[tokio::test]
async fn a_server_that_never_welcomes_is_a_timeout() {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    let server = tokio::spawn(async move {
        let (mut s, _) = listener.accept().await.unwrap();
        let mut sink = Vec::new();
        let _ = s.read_to_end(&mut sink).await;
    });
    let mut c = config("patient", port);
    c.connect_timeout = Duration::from_millis(300);
    let err = MoosClient::connect(c).await.unwrap_err();
    assert!(matches!(err, ClientError::Timeout { .. }), "{err}");
    server.abort();
}

#[tokio::test]
async fn bad_names_and_configs_are_rejected() {
    let db = mini_db().await;
    let (a, _mail) = connect("names", db.port()).await;
    assert!(matches!(
        a.register("", Duration::ZERO),
        Err(ClientError::EmptyVariable)
    ));
    assert!(matches!(
        a.notify_double("", 1.0),
        Err(ClientError::EmptyVariable)
    ));
    let mut c = config("", db.port());
    c.name.clear();
    assert!(matches!(
        MoosClient::connect(c).await,
        Err(ClientError::InvalidConfig(_))
    ));
    db.stop().await;
}

#[tokio::test]
async fn an_idle_connection_is_kept_alive() {
    let db = mini_db().await;
    let mut c = config("idle", db.port());
    c.heartbeat_period = Duration::from_millis(100);
    c.silence_timeout = Duration::from_millis(400);
    let (a, mut a_mail) = MoosClient::connect(c).await.unwrap();
    // Several silence timeouts long: only answered heartbeats keep the session.
    sleep(Duration::from_millis(1500)).await;
    assert_eq!(
        *a.state().borrow(),
        ConnectionState::Connected {
            community: "gobytest".into(),
            session: 1
        }
    );
    register_and_sync(&a, &mut a_mail, &[]).await;
    db.stop().await;
}

/// A server that welcomes clients and then never says anything again.
async fn mute_server() -> (u16, tokio::task::JoinHandle<()>) {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    let task = tokio::spawn(async move {
        let mut held = Vec::new();
        for _ in 0..3 {
            let Ok((mut s, _)) = listener.accept().await else {
                return;
            };
            let mut preamble = [0u8; PROTOCOL_PREAMBLE_LEN];
            s.read_exact(&mut preamble).await.unwrap();
            let mut prefix = [0u8; 4];
            s.read_exact(&mut prefix).await.unwrap();
            let mut rest = vec![0u8; wire::packet_length(prefix).unwrap() - 4];
            s.read_exact(&mut rest).await.unwrap();
            let mut welcome = Message::new(MessageKind::Welcome, "", 0.0);
            welcome.string = b"asynchronous".to_vec();
            welcome.community = "mute".into();
            s.write_all(&wire::encode_packet(&[welcome]).unwrap())
                .await
                .unwrap();
            held.push(s);
        }
    });
    (port, task)
}

#[tokio::test]
async fn a_silent_db_is_detected_and_the_client_reconnects() {
    let (port, server) = mute_server().await;
    let mut c = config("listener", port);
    c.heartbeat_period = Duration::from_millis(100);
    c.silence_timeout = Duration::from_millis(400);
    let (a, _mail) = MoosClient::connect(c).await.unwrap();
    wait_for_disconnect(&a).await;
    wait_for_session(&a, 2).await;
    server.abort();
}

#[tokio::test]
async fn the_client_reconnects_and_registers_again_after_the_db_restarts() {
    let db = mini_db().await;
    let port = db.port();
    let (a, mut a_mail, b) = round_trip(port, "re").await;

    db.stop().await;
    wait_for_disconnect(&a).await;
    wait_for_disconnect(&b).await;
    assert!(matches!(
        b.notify_string("GOBY_OUT", "lost"),
        Err(ClientError::NotConnected { .. })
    ));

    let db = MiniDb::start(("127.0.0.1", port), "gobytest")
        .await
        .unwrap();
    wait_for_session(&a, 2).await;
    wait_for_session(&b, 2).await;
    // a's registrations were replayed on the new connection.
    register_and_sync(&a, &mut a_mail, &[]).await;
    b.notify_string("GOBY_OUT", "hello again").unwrap();
    assert_eq!(
        mail_for(&mut a_mail, "GOBY_OUT").await.value,
        Value::String("hello again".into())
    );
    a.close().await;
    b.close().await;
    db.stop().await;
}

#[tokio::test]
async fn a_closed_client_leaves_the_db_and_refuses_work() {
    let db = mini_db().await;
    let (a, _mail) = connect("leaver", db.port()).await;
    a.notify_double("LAST_WORDS", 1.0).unwrap();
    a.close().await;
    assert_eq!(*a.state().borrow(), ConnectionState::Closed);
    assert!(matches!(
        a.notify_double("X", 1.0),
        Err(ClientError::Closed)
    ));
    // What was queued before close was sent.
    assert_eq!(db.value("LAST_WORDS"), Some(Value::Double(1.0)));
    timeout(LIMIT, async {
        while !db.clients().is_empty() {
            sleep(Duration::from_millis(10)).await;
        }
    })
    .await
    .expect("the DB still lists the closed client");
    db.stop().await;
}
