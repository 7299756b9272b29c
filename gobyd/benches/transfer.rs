//! Goodput of file transfers: how long `gobyd` takes to move a file of 1 KiB,
//! 10 KiB and 100 KiB from node 1 to node 2 (one hop) and from node 1 to
//! node 3 through node 2 (a relay), at 0 %, 10 % and 30 % packet loss
//! (data and acks alike), against what the link could carry.
//!
//! Every run is in virtual time (tokio's paused clock): the nodes are
//! `gobyd` daemons in this process on the acoustic simulator's in-process
//! channel, as in `tests/transfer.rs`, on a line 1500 m apart with a range
//! of 2000 m (1 and 3 do not hear each other), fixed TDMA with one slot per
//! node, Micro-Modem rate 5 in 6 s slots and rate 2 in 8 s slots, 0.5 s of
//! overhead on each packet, the `network` section's defaults but the route
//! (fragments that fill a frame, a window of 16). The losses are drawn
//! from each node's seeded generator, so every run gives the same table.
//!
//! `cargo bench -p gobyd --bench transfer` prints the table (Markdown),
//! then the sizes it rests on, measured by encoding: the bytes a fragment's
//! header takes in its frame, those of the stream header a transfer adds
//! once, those of a selective ack.
//!
//! Beside each lossy run the table gives what an ideal schedule reaches
//! at that loss ([`ideal`]): no protocol's acks, every sender knowing at
//! once what arrived, relays holding any number of packets. It is the
//! ceiling loss alone sets, drawn over many seeded runs.

#[path = "../tests/support/fleet.rs"]
mod fleet;
#[path = "../tests/support/node.rs"]
mod node;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use fleet::{data_dir, Fleet, Seen};
use gobyd::event::NetworkRequest;
use gobyd::internals::fragment::{self, Content};
use gobyd::internals::network::wire::{self, NetMessage};
use node::{Entry, Node, Simulator};
use protos::goby::acomms::protobuf::{fragment_ack, Fragment, FragmentAck, FragmentChannel};

/// A link: the modem's rate (Micro-Modem rate number) and the TDMA
/// slot, seconds.
#[derive(Debug, Clone, Copy)]
struct Link {
    rate: u32,
    slot_seconds: f64,
}

/// The links measured: rate 5 (8 frames of 256 bytes at 5300 bit/s) in
/// 6 s slots, rate 2 (3 frames of 64 bytes at 500 bit/s) in 8 s slots.
const LINKS: [Link; 2] = [
    Link {
        rate: 5,
        slot_seconds: 6.0,
    },
    Link {
        rate: 2,
        slot_seconds: 8.0,
    },
];
/// Time on the water added to each packet, seconds.
const OVERHEAD_SECONDS: f64 = 0.5;
/// Bodies sent, bytes.
const SIZES: [usize; 3] = [1024, 10 * 1024, 100 * 1024];
/// Chances of a packet's loss.
const LOSSES: [f64; 3] = [0.0, 0.1, 0.3];
/// A run not complete after this long (virtual) is reported so.
const LIMIT: Duration = Duration::from_secs(48 * 3600);
/// The clock's reading at the start of every run (2024-01-01T00:00:00Z,
/// µs): the TDMA slots fall at the same times in every run.
const EPOCH: i64 = 1_704_067_200_000_000;
/// Step of the virtual clock between two looks at the receiver.
const STEP: Duration = Duration::from_secs(1);

/// One node's configuration: nodes 1 to `n` on a line, TDMA 1 … `n`,
/// the route 1 … `n`.
fn config(
    link: Link,
    id: i32,
    n: i32,
    loss: f64,
    dir: &Path,
) -> protos::goby::apps::protobuf::GobydConfig {
    let driver = Simulator::line(n, 1500.0)
        .range(2000.0)
        .deferred_ack()
        .loss(loss)
        .seed(id as u64 + 90)
        .overhead(OVERHEAD_SECONDS);
    let nodes: Vec<i32> = (1..=n).collect();
    let route: String = nodes.iter().map(|i| format!("hop: {i} ")).collect();
    Node::new(id)
        .driver(driver)
        .tdma(&nodes, link.rate, link.slot_seconds)
        .queue(Entry::command().ack(true).ttl(7200))
        .json_tcp("")
        .data_dir(&data_dir(dir, id))
        .extra(&format!("network {{ route {{ {route}}} }}"))
        .config()
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

/// What one run measured.
struct Run {
    fragments: u32,
    /// Virtual time from `file_send` to the file written at the receiver.
    written: Option<Duration>,
    /// To the sender's `complete` (the receiver's ack of the last fragment).
    acknowledged: Option<Duration>,
    /// Wall time the run took.
    wall: Duration,
}

/// Sends `size` bytes from node 1 to node `n` over `n - 1` hops at `loss`.
async fn run(link: Link, n: i32, size: usize, loss: f64, scratch: &Path) -> Run {
    let wall = Instant::now();
    let dir = scratch.join(format!(
        "r{}-n{n}-s{size}-l{}",
        link.rate,
        (loss * 100.0) as u32
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let configs = (1..=n).map(|id| config(link, id, n, loss, &dir)).collect();
    let fleet = Fleet::start_at(configs, EPOCH).await;
    let body = pattern(size, size as u64 + 5);
    let file = dir.join("body.bin");
    std::fs::write(&file, &body).unwrap();
    let start = tokio::time::Instant::now();
    let sent = fleet
        .network(
            1,
            NetworkRequest::SendFile {
                dest: n,
                path: file,
                name: None,
            },
        )
        .await
        .expect("the file is taken");
    let id = sent["file_send"].as_u64().expect("a transfer id");
    let fragments = sent["transfer"]["fragments"].as_u64().unwrap_or(0) as u32;
    let mut written = None;
    let mut acknowledged = None;
    while start.elapsed() < LIMIT && (written.is_none() || acknowledged.is_none()) {
        tokio::time::sleep(STEP).await;
        let seen = fleet.seen();
        for s in &seen {
            let Seen::Transfer { node, event } = s else {
                continue;
            };
            if event.state != "complete" {
                continue;
            }
            if *node == n && event.name == "body.bin" && written.is_none() {
                let path = event.path.as_ref().expect("a received file has a path");
                assert_eq!(
                    std::fs::read(path).expect("the file is there"),
                    body,
                    "the file arrived changed"
                );
                written = Some(start.elapsed());
            }
            if *node == 1 && event.id == id && acknowledged.is_none() {
                acknowledged = Some(start.elapsed());
            }
        }
    }
    fleet.stop().await;
    let _ = std::fs::remove_dir_all(&dir);
    Run {
        fragments,
        written,
        acknowledged,
        wall: wall.elapsed(),
    }
}

/// The sizes of a link measured by encoding, bytes.
struct Sizes {
    /// A frame at the link's rate.
    frame: usize,
    /// Frames in a packet at the link's rate.
    frames: usize,
    /// Data bytes of each fragment (as the daemon chooses them).
    fragment_data: usize,
    /// A fragment's encoding less its data.
    fragment_header: usize,
    /// A transfer's stream header (a file named `body.bin`).
    stream_header: usize,
    /// A channel's binding, once a transfer on each hop.
    binding: usize,
    /// A selective ack, as encoded.
    ack: usize,
}

fn sizes(link: Link) -> Sizes {
    let spec = modemdriver::rate::spec(link.rate as i32).expect("a Micro-Modem rate");
    let config = config(link, 1, 2, 0.0, Path::new("/nonexistent"));
    let frame = gobyd::internals::network::frame_bytes(&config);
    let mut codec = dccl::Codec::new();
    wire::load(&mut codec).expect("the network types load");
    let fragment_data = gobyd::internals::network::fragment_data_bytes(&codec, frame)
        .expect("a fragment fits a frame");
    // A fragment as the sender writes it, near the end of a 100 KiB
    // transfer (short places: up to 2048 fragments): its header's fields
    // are of fixed width, so any would do.
    let data = vec![0x5A; fragment_data];
    let place = wire::Place {
        channel: 3,
        index: 1_700,
        long: false,
    };
    let encoded = codec
        .encode(
            &NetMessage::Fragment(Fragment {
                next_hop: 2,
                piece: wire::piece(place, &data).expect("the place fits"),
            })
            .to_dynamic(),
        )
        .expect("a fragment encodes");
    let binding = codec
        .encode(
            &NetMessage::Channel(FragmentChannel {
                next_hop: 2,
                origin: 1,
                final_dest: 3,
                hop_count: 0,
                lifetime: 86_000,
                transfer: 40_123,
                channel: 3,
            })
            .to_dynamic(),
        )
        .expect("a binding encodes")
        .len();
    assert!(encoded.len() <= frame, "the fragment overflows its frame");
    let ack = codec
        .encode(
            &NetMessage::FragmentAck(FragmentAck {
                next_hop: 2,
                origin: 3,
                final_dest: 1,
                hop_count: 0,
                lifetime: 1800,
                transfer: 40_123,
                have: 300,
                beyond: Some(vec![0xFF; 32]),
                outcome: fragment_ack::Outcome::Receiving as i32,
            })
            .to_dynamic(),
        )
        .expect("an ack encodes");
    let body = pattern(1024, 1);
    let stream = fragment::stream(
        Content::File {
            name: "body.bin".into(),
        },
        fragment_data as u16,
        &body,
    );
    Sizes {
        frame,
        frames: spec.frames as usize,
        fragment_data,
        fragment_header: encoded.len() - data.len(),
        stream_header: stream.len() - body.len(),
        binding,
        ack: ack.len(),
    }
}

fn seconds(d: Option<Duration>) -> String {
    d.map_or("not done".into(), |d| format!("{:.0}", d.as_secs_f64()))
}

fn main() {
    let scratch: PathBuf =
        std::env::temp_dir().join(format!("gobyd-bench-transfer-{}", std::process::id()));
    for link in LINKS {
        table(link, &scratch);
    }
    let _ = std::fs::remove_dir_all(&scratch);
}

/// Measures and prints one link's table.
fn table(link: Link, scratch: &Path) {
    let sizes = sizes(link);
    let slot = link.slot_seconds;
    let raw_bytes_per_second = (sizes.frame * sizes.frames) as f64 / slot;
    let raw_bps = raw_bytes_per_second * 8.0;
    println!(
        "## Rate {} ({} frames of {} bytes), {slot} s slots, {OVERHEAD_SECONDS} s packet overhead",
        link.rate, sizes.frames, sizes.frame
    );
    println!();
    println!(
        "Raw rate {raw_bps:.0} bit/s in a node's slot ({} bytes × {} frames / {slot} s). \
         TDMA limit: the raw rate × {} data bytes of each {}-byte frame / the slots in the cycle \
         (2 for one hop, 3 through the relay: each byte crosses each hop in its sender's slot).",
        sizes.frame, sizes.frames, sizes.fragment_data, sizes.frame
    );
    println!();
    println!(
        "| hops | size | loss | fragments | written at the receiver (virtual s) | acked at the sender (virtual s) | goodput (bit/s) | of the raw rate | of the TDMA limit | an ideal schedule at this loss: mean (its runs ≥ 90 %) | wall (s) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let mut ten_kib = Vec::new();
    for n in [2, 3] {
        for size in SIZES {
            for loss in LOSSES {
                let runtime = tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .start_paused(true)
                    .build()
                    .expect("a runtime");
                let r = runtime.block_on(run(link, n, size, loss, scratch));
                let goodput = r.written.map(|t| size as f64 * 8.0 / t.as_secs_f64());
                // Each byte crosses each hop in its sender's slot, one slot
                // of `n` in the cycle, in fragments of `fragment_data` of
                // the frame's bytes.
                let tdma_limit =
                    raw_bps * sizes.fragment_data as f64 / sizes.frame as f64 / f64::from(n);
                let packets = r.fragments.div_ceil(sizes.frames as u32);
                let (mean, at_90) = ideal(packets, (n - 1) as u32, loss);
                println!(
                    "| {} | {} KiB | {:.0} % | {} | {} | {} | {} | {} | {} | {:.0} % ({:.0} %) | {:.1} |",
                    n - 1,
                    size / 1024,
                    loss * 100.0,
                    r.fragments,
                    seconds(r.written),
                    seconds(r.acknowledged),
                    goodput.map_or("–".into(), |g| format!("{g:.0}")),
                    goodput.map_or("–".into(), |g| format!("{:.1} %", 100.0 * g / raw_bps)),
                    goodput.map_or("–".into(), |g| format!("{:.0} %", 100.0 * g / tdma_limit)),
                    100.0 * mean,
                    100.0 * at_90,
                    r.wall.as_secs_f64()
                );
                if size == 10 * 1024 {
                    ten_kib.push((n - 1, loss, r.written));
                }
            }
        }
    }
    println!();
    println!(
        "Per fragment: {} bytes of header in a {}-byte frame ({} bytes of data, {:.1} % overhead), measured by encoding.",
        sizes.fragment_header,
        sizes.frame,
        sizes.fragment_data,
        100.0 * sizes.fragment_header as f64 / sizes.frame as f64
    );
    println!(
        "Per transfer: a stream header of {} bytes (a file named body.bin), a channel's binding of {} bytes on each hop; a selective ack is {} bytes (its bitmap full).",
        sizes.stream_header, sizes.binding, sizes.ack
    );
    let limit = 10.0 * 1024.0 / raw_bytes_per_second;
    println!(
        "10 KiB at the raw rate: {limit:.0} s (every slot the sender's, every byte data); taken:"
    );
    for (hops, loss, written) in ten_kib {
        println!(
            "  {hops} hop{}, {:.0} % loss: {} s ({})",
            if hops == 1 { "" } else { "s" },
            loss * 100.0,
            seconds(written),
            written.map_or("–".into(), |t| format!(
                "{:.1}× the limit",
                t.as_secs_f64() / limit
            ))
        );
    }
    println!();
}

/// Runs of the ideal schedule drawn for each row.
const IDEAL_RUNS: u32 = 20_000;

/// What an ideal schedule reaches at `loss`, as a share of the TDMA limit:
/// `packets` packets (full ones) cross `hops` hops; in each cycle each
/// hop's sender, in hop order, sends one packet in its slot while it holds
/// one, lost with chance `loss`; every sender knows at once what arrived
/// (no acks take a slot) and a relay holds any number. A run's share is
/// `packets` / the cycles it took (1 with no loss). Returns the mean share
/// over [`IDEAL_RUNS`] seeded runs, and the fraction of runs at 0.9 or
/// more.
fn ideal(packets: u32, hops: u32, loss: f64) -> (f64, f64) {
    if packets == 0 || hops == 0 {
        return (1.0, 1.0);
    }
    // splitmix64: the same draws every run of the benchmark.
    let mut state = 0x5eed_u64 ^ u64::from(packets) << 16 ^ u64::from(hops);
    let mut lost = move || {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        ((z >> 11) as f64 / (1u64 << 53) as f64) < loss
    };
    let (mut total, mut at_90) = (0.0, 0u32);
    for _ in 0..IDEAL_RUNS {
        // held[h]: packets at hop h's sender; held[hops]: at the receiver.
        let mut held = vec![0u32; hops as usize + 1];
        held[0] = packets;
        let mut cycles = 0u32;
        while held[hops as usize] < packets {
            cycles += 1;
            for h in 0..hops as usize {
                if held[h] > 0 && !lost() {
                    held[h] -= 1;
                    held[h + 1] += 1;
                }
            }
        }
        let share = f64::from(packets) / f64::from(cycles);
        total += share;
        if share >= 0.9 {
            at_90 += 1;
        }
    }
    (
        total / f64::from(IDEAL_RUNS),
        f64::from(at_90) / f64::from(IDEAL_RUNS),
    )
}
