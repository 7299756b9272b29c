//! Transfers (messages larger than a frame, files) through a relay, in
//! virtual time: three `gobyd` in one process on the simulator's
//! in-process channel, on a line 1 – 2 – 3 1500 m apart with a range of
//! 2000 m (1 and 3 cannot hear each other), Goby3's static route `hop: 1
//! hop: 2 hop: 3`, fixed TDMA, 20 % of packets (data and acks) lost.
//!
//! - A 1.5 KB message and a 6 KB file from 1 to 3, with commands
//!   published meanwhile: the message arrives once, whole, and is acked
//!   end to end; the file is written at 3 with the same bytes; the
//!   commands (higher priority) overtake the file.
//! - A 50 KB file from 1 to 3 with the receiver killed (its task aborted)
//!   a third of the way and the sender two thirds of the way, each started
//!   again a minute later on its data directory: the transfer resumes and
//!   completes, the file written once with the same bytes.

mod support;

use std::path::Path;
use std::time::Duration;

use gobyd::event::NetworkRequest;
use prost_reflect::{DynamicMessage, ReflectMessage, Value};
use protos::goby::example::Command;
use support::daemon::{publish_command, scratch};
use support::fleet::{data_dir, Fleet, Seen};
use support::node::{Entry, Node, Simulator};

const BLOB_PROTO: &str = r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package test;
message Blob {
  option (dccl.msg) = { id: 126 max_bytes: 2100 codec_version: 4 };
  required int32 destination = 1 [(dccl.field) = { min: 0 max: 31 in_head: true }];
  required bytes data = 2 [(dccl.field).max_length = 2000];
}
"#;

/// Node `id` of the line 1 – 2 – 3: fixed TDMA at `rate` in `slot`-second
/// slots, `loss` of the packets (data and acks) lost, commands acked.
fn line_node(id: i32, dir: &Path, rate: u32, slot: f64, loss: f64) -> Node {
    let driver = Simulator::line(3, 1500.0)
        .range(2000.0)
        .deferred_ack()
        .loss(loss)
        .seed(id as u64 + 90)
        .overhead(0.5);
    Node::new(id)
        .driver(driver)
        .tdma(&[1, 2, 3], rate, slot)
        .queue(Entry::command().ack(true).ttl(7200))
        .json_tcp("")
        .data_dir(&data_dir(dir, id))
}

/// The configurations of the line 1 – 2 – 3 (as [`line_node`]) with
/// Goby3's static route `hop: 1 hop: 2 hop: 3` and the network layer on.
fn routed_line(
    dir: &Path,
    rate: u32,
    slot: f64,
    loss: f64,
) -> Vec<protos::goby::apps::protobuf::GobydConfig> {
    (1..=3)
        .map(|id| {
            line_node(id, dir, rate, slot, loss)
                .extra("network { route { hop: 1 hop: 2 hop: 3 } }")
                .config()
        })
        .collect()
}

fn config(id: i32, dir: &Path, rate: u32, slot: f64) -> protos::goby::apps::protobuf::GobydConfig {
    let proto = dir.join("blob.proto");
    if !proto.exists() {
        std::fs::write(&proto, BLOB_PROTO).unwrap();
    }
    line_node(id, dir, rate, slot, 0.2)
        .queue(
            Entry::new("test.Blob")
                .role("DESTINATION_ID", "destination")
                .ack(true)
                .ttl(7200),
        )
        .extra(&format!("dccl {{ proto_file: \"{}\" }}", proto.display()))
        .extra("network { route { hop: 1 hop: 2 hop: 3 } resend_seconds: 600 }")
        .config()
}

/// A `test.Blob` to `destination` holding `data`.
fn blob(dir: &Path, destination: i32, data: Vec<u8>) -> DynamicMessage {
    let pool = dccl::compile_protos(&[dir.join("blob.proto")], &[] as &[&Path]).unwrap();
    let mut m = DynamicMessage::new(pool.get_message_by_name("test.Blob").unwrap());
    m.set_field_by_name("destination", Value::I32(destination));
    m.set_field_by_name("data", Value::Bytes(data.into()));
    m
}

async fn publish(
    publisher: &tokio::sync::mpsc::Sender<gobyd::event::Publish>,
    message: DynamicMessage,
) -> serde_json::Value {
    let (reply, answer) = tokio::sync::oneshot::channel();
    publisher
        .send(gobyd::event::Publish::new(message, reply))
        .await
        .unwrap();
    let accepted = answer.await.unwrap().expect("accepted");
    serde_json::json!({ "id": accepted.id })
}

/// Bytes that do not repeat in any short period.
fn pattern(len: usize, seed: u64) -> Vec<u8> {
    let mut x = seed | 1;
    (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}

fn note(message: &DynamicMessage) -> String {
    message
        .transcode_to::<Command>()
        .map(|c| c.note().to_string())
        .unwrap_or_default()
}

/// Waits (virtual time) until `done` holds, at most `limit`.
/// Node `from` sends the file at `path` to node `dest`; its answer
/// (`file_send`, the transfer).
async fn send_file(
    fleet: &Fleet,
    from: i32,
    dest: i32,
    path: std::path::PathBuf,
) -> serde_json::Value {
    fleet
        .network(
            from,
            NetworkRequest::SendFile {
                dest,
                path,
                name: None,
            },
        )
        .await
        .expect("the file is taken")
}

async fn until(fleet: &Fleet, limit: Duration, done: impl Fn(&[Seen]) -> bool) -> bool {
    let end = tokio::time::Instant::now() + limit;
    while tokio::time::Instant::now() < end {
        if done(&fleet.seen()) {
            return true;
        }
        tokio::time::sleep(Duration::from_secs(10)).await;
    }
    done(&fleet.seen())
}

fn transfer_at(seen: &[Seen], node: i32, state: &str) -> Vec<gobyd::event::TransferEvent> {
    seen.iter()
        .filter_map(|s| match s {
            Seen::Transfer { node: n, event } if *n == node && event.state == state => {
                Some(event.clone())
            }
            _ => None,
        })
        .collect()
}

#[tokio::test(start_paused = true)]
async fn a_large_message_and_a_file_cross_the_relay_and_commands_overtake_them() {
    let dir = scratch("transfer", "relay");
    let configs = (1..=3).map(|id| config(id, &dir, 2, 8.0)).collect();
    let fleet = Fleet::start(configs).await;
    let data = pattern(1500, 7);
    let accepted = publish(fleet.publisher(1), blob(&dir, 3, data.clone())).await;
    let message_id = accepted["id"].as_u64().expect("an id");
    let file = dir.join("survey.bin");
    let content = pattern(6000, 11);
    std::fs::write(&file, &content).unwrap();
    let sent = send_file(&fleet, 1, 3, file.clone()).await;
    let file_id = sent["file_send"].as_u64().unwrap();
    assert_eq!(sent["joined"], false);
    // Sending it again joins the transfer.
    let again = send_file(&fleet, 1, 3, file.clone()).await;
    assert_eq!(
        (again["file_send"].as_u64(), &again["joined"]),
        (Some(file_id), &true.into())
    );
    tokio::time::sleep(Duration::from_secs(60)).await;
    for i in 0..4 {
        publish_command(fleet.publisher(1), 3, &format!("cmd{i}")).await;
    }
    let done = until(&fleet, Duration::from_secs(4 * 3600), |seen| {
        let acked = |id: u64| {
            seen.iter()
                .any(|s| matches!(s, Seen::Acked { node: 1, id: Some(i), .. } if *i == id))
        };
        let commands = seen
            .iter()
            .filter(|s| matches!(s, Seen::Acked { node: 1, message, .. } if note(message).starts_with("cmd")))
            .count();
        acked(message_id)
            && transfer_at(seen, 1, "complete").iter().any(|e| e.id == file_id)
            && commands >= 4
    })
    .await;
    let seen = fleet.seen();
    assert!(
        done,
        "not done in 4 virtual hours: {:?}",
        transfer_at(&seen, 3, "receiving").last()
    );
    // The message: once, whole, at 3; acked once at 1, by 3.
    let blobs: Vec<&Seen> = seen
        .iter()
        .filter(|s| matches!(s, Seen::Delivered { message, .. } if message.descriptor().full_name() == "test.Blob"))
        .collect();
    assert_eq!(blobs.len(), 1, "{blobs:?}");
    let Seen::Delivered {
        node, src, message, ..
    } = blobs[0]
    else {
        unreachable!()
    };
    assert_eq!((*node, *src), (3, 1));
    assert_eq!(
        message
            .get_field_by_name("data")
            .unwrap()
            .as_bytes()
            .unwrap()
            .as_ref(),
        data.as_slice()
    );
    let acks: Vec<&Seen> = seen
        .iter()
        .filter(|s| matches!(s, Seen::Acked { id: Some(id), .. } if *id == message_id))
        .collect();
    assert!(
        matches!(acks.as_slice(), [Seen::Acked { node: 1, by: 3, .. }]),
        "{acks:?}"
    );
    // The file: written once at 3 with the same bytes, complete at 1.
    let written = transfer_at(&seen, 3, "complete");
    let file_event = written
        .iter()
        .find(|e| e.name == "survey.bin")
        .expect("the file arrived");
    let path = file_event.path.clone().expect("its path");
    assert_eq!(std::fs::read(&path).unwrap(), content);
    // Private, as every file of the data directory: the file 0600 in a
    // directory created 0700.
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = |p: &std::path::Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        let path = std::path::Path::new(&path);
        assert_eq!(mode(path), 0o600, "{}", path.display());
        let parent = path.parent().unwrap();
        assert_eq!(mode(parent), 0o700, "{}", parent.display());
    }
    assert!(transfer_at(&seen, 1, "complete")
        .iter()
        .any(|e| e.id == file_id));
    assert_eq!(written.iter().filter(|e| e.name == "survey.bin").count(), 1);
    // The message's transfer is named by its type at the receiver too.
    assert_eq!(
        written.iter().filter(|e| e.name == "test.Blob").count(),
        1,
        "{written:?}"
    );
    // The commands: each once at 3, acked end to end, before the file
    // was whole.
    let file_done = seen
        .iter()
        .position(|s| matches!(s, Seen::Transfer { node: 3, event } if event.name == "survey.bin" && event.state == "complete"))
        .unwrap();
    for i in 0..4 {
        let text = format!("cmd{i}");
        let at: Vec<usize> = seen
            .iter()
            .enumerate()
            .filter(|(_, s)| matches!(s, Seen::Delivered { node: 3, message, .. } if note(message) == text))
            .map(|(k, _)| k)
            .collect();
        assert_eq!(at.len(), 1, "{text} delivered {} times", at.len());
        assert!(at[0] < file_done, "{text} came after the file");
    }
    fleet.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(start_paused = true)]
async fn a_50_kb_file_survives_restarts_of_both_ends() {
    let dir = scratch("transfer", "restarts");
    let configs = (1..=3).map(|id| config(id, &dir, 5, 6.0)).collect();
    let mut fleet = Fleet::start(configs).await;
    let (id, fragments, content) = send_a_third(&mut fleet, &dir, "mission.log", 50, 3).await;
    fleet.kill(3).await;
    tokio::time::sleep(Duration::from_secs(60)).await;
    fleet.start_node(3).await;
    let killed_receiver_at = held_at_3(&fleet.seen());
    assert!(
        until(&fleet, Duration::from_secs(3600), |s| held_at_3(s)
            >= 2 * fragments / 3)
        .await
    );
    fleet.kill(1).await;
    tokio::time::sleep(Duration::from_secs(60)).await;
    fleet.start_node(1).await;
    let killed_sender_at = held_at_3(&fleet.seen());
    let done = until(&fleet, Duration::from_secs(4 * 3600), |s| {
        transfer_at(s, 1, "complete").iter().any(|e| e.id == id)
    })
    .await;
    let seen = fleet.seen();
    assert!(done, "not complete in 4 virtual hours");
    let written = transfer_at(&seen, 3, "complete");
    assert_eq!(written.len(), 1, "{written:?}");
    assert_eq!(
        std::fs::read(written[0].path.as_ref().unwrap()).unwrap(),
        content
    );
    assert!(transfer_at(&seen, 3, "failed").is_empty());
    eprintln!(
        "50 KB in {fragments} fragments: receiver killed at {killed_receiver_at}, sender at {killed_sender_at} held; complete"
    );
    fleet.stop().await;
    // Nothing left under way at either end.
    for node in [1, 3] {
        let status = gobyd::internals::network::transfers::Transfers::open(
            node,
            settings_for_inspection(&dir, node),
            &data_dir(&dir, node).join("transfers.log"),
            0,
            &queue::Entropy::System,
        )
        .unwrap()
        .status();
        assert!(status.is_empty(), "node {node}: {status:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The relay holds the transfer's channels (its bindings on record, its
/// own channel's fragments in its journal): killed a third of the way and
/// started again a minute later, it takes the transfer up, and the file is
/// written once with the same bytes.
#[tokio::test(start_paused = true)]
async fn a_file_survives_a_restart_of_the_relay() {
    let dir = scratch("transfer", "relay-restart");
    let configs = (1..=3).map(|id| config(id, &dir, 5, 6.0)).collect();
    let mut fleet = Fleet::start(configs).await;
    let (id, _, content) = send_a_third(&mut fleet, &dir, "sidescan.bin", 30, 5).await;
    fleet.kill(2).await;
    tokio::time::sleep(Duration::from_secs(60)).await;
    fleet.start_node(2).await;
    let done = until(&fleet, Duration::from_secs(4 * 3600), |s| {
        transfer_at(s, 1, "complete").iter().any(|e| e.id == id)
    })
    .await;
    let seen = fleet.seen();
    assert!(
        done,
        "not complete in 4 virtual hours: {:?}",
        transfer_at(&seen, 3, "receiving").last()
    );
    let written = transfer_at(&seen, 3, "complete");
    assert_eq!(written.len(), 1, "{written:?}");
    assert_eq!(
        std::fs::read(written[0].path.as_ref().unwrap()).unwrap(),
        content
    );
    assert!(transfer_at(&seen, 3, "failed").is_empty());
    fleet.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}

/// Node 1 sends node 3 a file of `kb` KiB (named `name`, its bytes from
/// `seed`) through node 2; returns once node 3 holds a third of its
/// fragments: the transfer's id, its fragments and the file's bytes.
async fn send_a_third(
    fleet: &mut Fleet,
    dir: &Path,
    name: &str,
    kb: usize,
    seed: u64,
) -> (u64, u32, Vec<u8>) {
    let file = dir.join(name);
    let content = pattern(kb * 1024, seed);
    std::fs::write(&file, &content).unwrap();
    let sent = send_file(fleet, 1, 3, file.clone()).await;
    let id = sent["file_send"].as_u64().unwrap();
    let fragments = sent["transfer"]["fragments"].as_u64().unwrap() as u32;
    assert!(
        until(fleet, Duration::from_secs(3600), |s| held_at_3(s)
            >= fragments / 3)
        .await
    );
    (id, fragments, content)
}

/// Fragments node 3 holds of the transfer it is receiving.
fn held_at_3(seen: &[Seen]) -> u32 {
    transfer_at(seen, 3, "receiving")
        .last()
        .map_or(0, |e| e.held)
}

fn settings_for_inspection(
    dir: &Path,
    node: i32,
) -> gobyd::internals::network::transfers::Settings {
    gobyd::internals::network::transfers::Settings {
        fragment_size: 64,
        window: 1,
        resend_after: 0,
        max_bytes: 1 << 24,
        relay_window: 1,
        receive_dir: data_dir(dir, node).join("inspect"),
        serve_dir: None,
        file_ttl: 1,
        fragment_ttl: 0,
        ack_ttl: 0,
        remember: 0,
        silence: 300_000_000,
    }
}

/// A relay's packet whose hop ack is lost leaves its fragments waiting
/// there to go again, though the receiver has them: the receiver's
/// selective ack, which the relay forwards, says so, and they leave the
/// relay's queue unsent. With every hop ack from 3 to 2 lost but the
/// first (its selective acks still heard), 2 KiB from 1 to 3 through 2 arrive, and
/// the relay puts no fragment on the water twice (it did every one, some
/// many times, each waiting its hop's ack).
#[tokio::test(start_paused = true)]
async fn a_relay_does_not_send_again_fragments_the_receiver_says_it_has() {
    use modemdriver::sim::medium::Airborne;
    use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Arc;

    let dir = scratch("transfer", "relay-held");
    let configs = routed_line(&dir, 2, 8.0, 0.0);
    let fleet = Fleet::start(configs).await;
    // Frames of the relay's data packets to 3 (a fragment each, but the
    // channel's binding).
    let relayed = Arc::new(AtomicUsize::new(0));
    let count = relayed.clone();
    let acks = AtomicUsize::new(0);
    fleet
        .medium()
        .set_filter(Arc::new(move |packet: &Arc<Airborne>, to: i32| {
            let t = &packet.transmission;
            // The first passes: the binding of the relay's channel to the
            // transfer (fragments go on it once it is acknowledged).
            if packet.src == 3
                && to == 2
                && t.r#type() == TransmissionType::Ack
                && acks.fetch_add(1, Ordering::SeqCst) > 0
            {
                return None;
            }
            if packet.src == 2 && to == 3 && t.r#type() == TransmissionType::Data {
                count.fetch_add(t.frame.len(), Ordering::SeqCst);
            }
            Some(packet.clone())
        }));
    let file = dir.join("log.bin");
    let content = pattern(2 * 1024, 23);
    std::fs::write(&file, &content).unwrap();
    let sent = send_file(&fleet, 1, 3, file).await;
    let fragments = sent["transfer"]["fragments"].as_u64().unwrap() as usize;
    assert!(
        until(&fleet, Duration::from_secs(3600), |s| {
            !transfer_at(s, 3, "complete").is_empty() && !transfer_at(s, 1, "complete").is_empty()
        })
        .await,
        "2 KiB through the relay, written and its end heard, within a virtual hour"
    );
    let complete = transfer_at(&fleet.seen(), 3, "complete");
    assert_eq!(
        std::fs::read(complete[0].path.as_ref().unwrap()).unwrap(),
        content
    );
    // Each fragment once, and the channel's binding.
    let frames = relayed.load(Ordering::SeqCst);
    assert!(
        frames <= fragments + 3,
        "{frames} frames from the relay to the receiver for {fragments} fragments"
    );
    fleet.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}

/// A relay has one slot for both directions, and a packet goes to one
/// node: the receiver's selective acks, forwarded to the origin at once,
/// took the relay's packet from the fragments every cycle (half the TDMA
/// limit). Held back while fragments wait, the relay's slot carries
/// fragments: 10 KiB from 1 to 3 through 2 in 64-byte frames, no loss,
/// arrive at 90 % of the TDMA limit or more (the limit: a slot's frames of fragment data in
/// each cycle of three slots, as `docs/performance.md` measures it).
#[tokio::test(start_paused = true)]
async fn a_file_through_the_relay_keeps_pace_with_the_tdma_limit() {
    let dir = scratch("transfer", "pace");
    // Rate 2 (3 frames of 64 bytes) in 8 s slots: 178 fragments, about 60
    // cycles, so that the start (the pipeline filling) weighs little.
    let (rate, slot) = (2, 8.0);
    let configs = routed_line(&dir, rate, slot, 0.0);
    let frame = gobyd::internals::network::frame_bytes(&configs[0]);
    let mut codec = dccl::Codec::new();
    gobyd::internals::network::wire::load(&mut codec).unwrap();
    let data = gobyd::internals::network::fragment_data_bytes(&codec, frame).unwrap();
    let frames = modemdriver::rate::spec(rate as i32).unwrap().frames as f64;
    let limit_bps = (frame as f64 * frames * 8.0 / slot) * data as f64 / frame as f64 / 3.0;
    let fleet = Fleet::start(configs).await;
    let file = dir.join("survey.bin");
    let content = pattern(10 * 1024, 17);
    std::fs::write(&file, &content).unwrap();
    let start = tokio::time::Instant::now();
    send_file(&fleet, 1, 3, file).await;
    let mut written = None;
    while written.is_none() && start.elapsed() < Duration::from_secs(4 * 3600) {
        tokio::time::sleep(Duration::from_secs(1)).await;
        if !transfer_at(&fleet.seen(), 3, "complete").is_empty() {
            written = Some(start.elapsed());
        }
    }
    let written = written.expect("written at 3 within four virtual hours");
    let seen = fleet.seen();
    let complete = transfer_at(&seen, 3, "complete");
    assert_eq!(
        std::fs::read(complete[0].path.as_ref().unwrap()).unwrap(),
        content
    );
    // Its progress at the receiver: each event names the file, its size
    // and its fragments (the first comes once its header is held), about
    // one a sixteenth of its fragments.
    let progress = transfer_at(&seen, 3, "receiving");
    assert!((2..=17).contains(&progress.len()), "{progress:?}");
    for (k, e) in progress.iter().enumerate() {
        assert_eq!(
            (e.name.as_str(), e.bytes, e.fragments),
            ("survey.bin", content.len() as u64, complete[0].fragments),
            "{e:?}"
        );
        assert!(k == 0 || e.held > progress[k - 1].held, "{progress:?}");
    }
    let goodput = content.len() as f64 * 8.0 / written.as_secs_f64();
    assert!(
        goodput >= 0.9 * limit_bps,
        "10 KiB through the relay in {:.0} s: {goodput:.0} bit/s, {:.0} % of the TDMA limit ({limit_bps:.0} bit/s)",
        written.as_secs_f64(),
        100.0 * goodput / limit_bps
    );
    // The origin hears the end all the same.
    assert!(
        until(&fleet, Duration::from_secs(600), |s| !transfer_at(
            s, 1, "complete"
        )
        .is_empty())
        .await,
        "the sender never heard the transfer complete"
    );
    fleet.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(start_paused = true)]
async fn a_short_file_goes_in_the_packet_of_its_channels_binding() {
    // Rate 5 (8 frames of 256 bytes) in 6 s slots of a cycle of three:
    // 1 KiB is 5 fragments, which fit in the sender's packet beside the
    // binding of a clean channel (the sender never bound one, or the last
    // transfer on it ended by the receiver's word). Bound on an unclean
    // channel, the fragments would wait a cycle for the binding's ack.
    let dir = scratch("transfer", "early");
    let (rate, slot) = (5, 6.0);
    let configs = routed_line(&dir, rate, slot, 0.0);
    let fleet = Fleet::start(configs).await;
    let cycle = Duration::from_secs_f64(3.0 * slot);
    // More transfers than channels (16): the later ones reuse channels
    // made clean by the receiver's word.
    for round in 0..18usize {
        let file = dir.join(format!("note-{round}.bin"));
        let content = pattern(1024, 40 + round as u64);
        std::fs::write(&file, &content).unwrap();
        let start = tokio::time::Instant::now();
        send_file(&fleet, 1, 2, file).await;
        let mut written = None;
        while written.is_none() && start.elapsed() < Duration::from_secs(600) {
            tokio::time::sleep(Duration::from_millis(100)).await;
            let complete = transfer_at(&fleet.seen(), 2, "complete");
            if complete.len() > round {
                written = Some((start.elapsed(), complete[round].clone()));
            }
        }
        let (took, event) = written.expect("written at 2 within ten virtual minutes");
        assert_eq!(
            std::fs::read(event.path.as_ref().unwrap()).unwrap(),
            content
        );
        // The first (a channel never bound): at most a cycle waiting for
        // the sender's slot, then that slot. The next ones are sent as
        // the sender hears the last end, in the receiver's slot: the
        // sender's slot comes within the cycle, and the file in it.
        let bound = if round == 0 {
            cycle + Duration::from_secs_f64(slot)
        } else {
            cycle
        };
        assert!(
            took < bound,
            "transfer {round}: written after {:.1} s, a cycle is {:.0} s",
            took.as_secs_f64(),
            cycle.as_secs_f64()
        );
        // The sender hears the end (the channel is clean again).
        let heard = tokio::time::Instant::now() + Duration::from_secs(600);
        while transfer_at(&fleet.seen(), 1, "complete").len() <= round {
            assert!(
                tokio::time::Instant::now() < heard,
                "the sender never heard transfer {round} complete"
            );
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }
    fleet.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(start_paused = true)]
async fn transfers_on_clean_channels_stay_whole_when_bindings_are_lost() {
    // As above, with 30 % of packets lost (bindings, fragments and acks
    // alike) and each file sent before the last one's end reached the
    // sender: fragments come without their binding, to a channel bound to
    // a transfer that ended or to none, and every file is still written
    // once with its own bytes.
    let dir = scratch("transfer", "early-lossy");
    let (rate, slot) = (5, 6.0);
    let configs = routed_line(&dir, rate, slot, 0.3);
    let fleet = Fleet::start(configs).await;
    let mut contents = Vec::new();
    for round in 0..20usize {
        let file = dir.join(format!("note-{round}.bin"));
        let content = pattern(700 + 40 * round, 90 + round as u64);
        std::fs::write(&file, &content).unwrap();
        contents.push(content);
        send_file(&fleet, 1, 2, file).await;
        // The next once this one is written at the receiver.
        let limit = tokio::time::Instant::now() + Duration::from_secs(3600);
        while transfer_at(&fleet.seen(), 2, "complete").len() <= round {
            assert!(
                tokio::time::Instant::now() < limit,
                "transfer {round} not written within a virtual hour"
            );
            tokio::time::sleep(Duration::from_millis(500)).await;
        }
    }
    assert!(
        until(&fleet, Duration::from_secs(3600), |s| transfer_at(
            s, 1, "complete"
        )
        .len()
            == 20)
        .await,
        "the sender heard {} of 20 transfers complete",
        transfer_at(&fleet.seen(), 1, "complete").len()
    );
    let seen = fleet.seen();
    let written = transfer_at(&seen, 2, "complete");
    assert_eq!(written.len(), 20, "each written once");
    let mut bytes: Vec<Vec<u8>> = written
        .iter()
        .map(|e| std::fs::read(e.path.as_ref().unwrap()).unwrap())
        .collect();
    bytes.sort();
    contents.sort();
    assert_eq!(bytes, contents);
    assert!(transfer_at(&seen, 2, "failed").is_empty());
    fleet.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}

/// A broadcast is never fragmented: one larger than every frame the node
/// could send (a rate-5 frame here, less the identity trailer) is refused
/// when published, saying why, rather than accepted to wait for good; a
/// broadcast that fits is accepted, and a message as large to one node
/// goes in fragments.
#[tokio::test(start_paused = true)]
async fn a_broadcast_larger_than_every_frame_is_refused_when_published() {
    let dir = scratch("transfer", "broadcast");
    let configs = (1..=3).map(|id| config(id, &dir, 2, 8.0)).collect();
    let fleet = Fleet::start(configs).await;
    let answer = |message: DynamicMessage| {
        let publisher = fleet.publisher(1).clone();
        async move {
            let (reply, answer) = tokio::sync::oneshot::channel();
            publisher
                .send(gobyd::event::Publish::new(message, reply))
                .await
                .unwrap();
            answer.await.unwrap()
        }
    };
    let refused = answer(blob(&dir, 0, pattern(1500, 3)))
        .await
        .expect_err("a broadcast of 1500 bytes is refused");
    assert!(
        refused.contains("test.Blob: a broadcast of 15")
            && refused.contains("larger than every frame this node sends (at most 252 bytes"),
        "{refused}"
    );
    answer(blob(&dir, 0, pattern(100, 3)))
        .await
        .expect("a broadcast that fits a frame is accepted");
    answer(blob(&dir, 3, pattern(1500, 3)))
        .await
        .expect("the same to one node goes in fragments");
    fleet.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}

/// A transfer to a node that never answers (node 9: on the subnet, so
/// sent straight to it, but no such node) does not hold up a transfer
/// through another hop for its lifetime. Before, its fragments and its
/// channel's binding went again at every slot of node 1 (the queue's next
/// messages were theirs) and the window was the node's: the file to node
/// 3 was not written in a virtual hour (the first transfer's lifetime is
/// a day). Now the window is each next hop's, and a hop that acknowledges
/// nothing for twenty cycles (here 480 s) has this node's messages toward
/// it taken back out of the queue, to be tried again later.
#[tokio::test(start_paused = true)]
async fn a_transfer_to_a_silent_node_does_not_hold_up_the_others() {
    let dir = scratch("transfer", "silent");
    let configs = (1..=3).map(|id| config(id, &dir, 2, 8.0)).collect();
    let fleet = Fleet::start(configs).await;
    let lost = dir.join("lost.bin");
    std::fs::write(&lost, pattern(3000, 5)).unwrap();
    let first = send_file(&fleet, 1, 9, lost).await;
    assert_eq!(first["transfer"]["state"], "sending", "{first}");
    tokio::time::sleep(Duration::from_secs(120)).await;
    let file = dir.join("survey.bin");
    let content = pattern(1024, 6);
    std::fs::write(&file, &content).unwrap();
    let start = tokio::time::Instant::now();
    send_file(&fleet, 1, 3, file).await;
    let done = until(&fleet, Duration::from_secs(3600), |s| {
        transfer_at(s, 3, "complete")
            .iter()
            .any(|e| e.name == "survey.bin")
    })
    .await;
    let seen = fleet.seen();
    assert!(
        done,
        "the file to node 3 not written within a virtual hour: {:?}",
        transfer_at(&seen, 3, "receiving").last()
    );
    // Written in about 600 s here (20 % loss, through the relay): the
    // first 480 s while node 9 is not yet silent share node 1's slots.
    assert!(
        start.elapsed() < Duration::from_secs(1800),
        "the file to node 3 took {:?}",
        start.elapsed()
    );
    let written: Vec<_> = transfer_at(&seen, 3, "complete")
        .into_iter()
        .filter(|e| e.name == "survey.bin")
        .collect();
    assert_eq!(
        std::fs::read(written[0].path.as_ref().unwrap()).unwrap(),
        content
    );
    // The transfer to node 9 is still under way, not failed.
    assert!(transfer_at(&seen, 1, "failed").is_empty());
    fleet.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
}
