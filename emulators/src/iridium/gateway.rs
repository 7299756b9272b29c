//! An emulated Iridium gateway: the satellite side of the emulated
//! transceivers' sessions, and DirectIP towards the shore.
//!
//! - MO: each message a transceiver sends in a session is delivered to
//!   the shore's DirectIP listener (`mo_destination`), one TCP connection
//!   per message (header, location, payload), in order; while the shore
//!   does not accept the connection, delivery is tried again every
//!   `mo_retry` (nothing is dropped). With `mo_webhook` (the emulated
//!   RockBLOCK service, [`super::rockblock`]) each message is POSTed to
//!   the shore's webhook instead, with its JWT; a post not answered 200 is
//!   made again after `mo_retry`, doubled at each failure in a row up to
//!   `mo_webhook.max_retry`, as RockBLOCK retries.
//! - MT: the gateway's DirectIP listener takes MT messages (header IE
//!   0x41, payload 0x42) and answers each with its confirmation (0x44):
//!   its place in the transceiver's MT queue, or a refusal (unknown IMEI,
//!   a payload larger than `mt_limit`, a full queue, or, while
//!   [`Gateway::set_refusing`] says so, resources unavailable). The
//!   disposition flag 0x0001 empties the queue first.
//! - Ring alerts: a transceiver with MT messages queued is sent a ring
//!   alert when a message comes, and again every `ring_repeat` up to
//!   `ring_count` times while the queue is not empty.
//! - A session takes the MO message and gives the first MT message queued.
//! - RUDICS: a call dialled by a voice-enabled transceiver, whatever the
//!   number, is connected to the shore's RUDICS server (`rudics_shore`)
//!   after `dial_time` (see [`super::start`]).

use std::collections::{HashMap, VecDeque};
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, Notify};
use tokio::task::JoinHandle;
use tokio::time::Instant;

use super::rockblock::WebhookTarget;
use super::transceiver::GatewaySession;
use modemdriver::iridium::directip::{
    self, disposition, mt_status, MoHeader, MoLocation, MoMessage, MtConfirmation, MtMessage,
};

/// Most MT messages queued for one transceiver.
pub const MT_QUEUE_LIMIT: usize = 50;

/// How long a DirectIP connection may take to say its message.
pub const CONNECTION_TIMEOUT: Duration = Duration::from_secs(5);

/// Settings of the emulated gateway.
#[derive(Debug, Clone, PartialEq)]
pub struct GatewayConfig {
    /// The shore's DirectIP MO listener (`None`: MO messages are kept).
    pub mo_destination: Option<SocketAddr>,
    /// The shore's RockBLOCK webhook: MO messages are posted there rather
    /// than to `mo_destination`.
    pub mo_webhook: Option<WebhookTarget>,
    /// Where the gateway's DirectIP MT listener binds (port 0: any free).
    pub mt_bind: SocketAddr,
    /// Largest MT payload taken (270 bytes for a 9602/9603).
    pub mt_limit: usize,
    /// Between attempts to deliver an MO message the shore did not take.
    pub mo_retry: Duration,
    /// Between ring alerts for a queue not emptied.
    pub ring_repeat: Duration,
    /// Ring alerts sent per MT message at most.
    pub ring_count: u32,
    /// The location given with every MO message (degrees; CEP radius km).
    pub location: Option<MoLocation>,
    /// The shore's RUDICS server, where calls are connected (`None`: a
    /// call is answered `NO ANSWER`).
    pub rudics_shore: Option<SocketAddr>,
    /// How long a call takes to connect (a real one: 10 to 20 s).
    pub dial_time: Duration,
}

impl Default for GatewayConfig {
    fn default() -> Self {
        GatewayConfig {
            mo_destination: None,
            mo_webhook: None,
            mt_bind: SocketAddr::from(([127, 0, 0, 1], 0)),
            mt_limit: 270,
            mo_retry: Duration::from_secs(1),
            ring_repeat: Duration::from_secs(20),
            ring_count: 5,
            location: None,
            rudics_shore: None,
            dial_time: Duration::from_secs(1),
        }
    }
}

/// What the gateway did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct GatewayLog {
    /// MO messages taken from transceivers.
    pub mo_received: u64,
    /// MO messages delivered to the shore (over DirectIP, or posted to the
    /// webhook and answered 200).
    pub mo_delivered: u64,
    /// Webhook posts the shore refused (an HTTP status other than 200),
    /// by status; they are posted again.
    pub mo_refused: Vec<u16>,
    /// Attempts to deliver an MO message that failed (shore down).
    pub mo_delivery_failures: u64,
    /// MT messages taken from the shore.
    pub mt_accepted: u64,
    /// MT messages refused, by status.
    pub mt_refused: Vec<i16>,
    /// MT messages given to transceivers.
    pub mt_delivered: u64,
    /// Ring alerts sent.
    pub rings: u64,
}

#[derive(Debug)]
struct Modem {
    rings: mpsc::UnboundedSender<()>,
    queue: VecDeque<(Vec<u8>, u16)>,
    next_mtmsn: u16,
    rings_left: u32,
    next_ring: Option<Instant>,
}

#[derive(Debug, Default)]
struct State {
    modems: HashMap<String, Modem>,
    mo_out: VecDeque<MoMessage>,
    cdr: u32,
    auto_id: u32,
    refusing: bool,
    log: GatewayLog,
}

#[derive(Debug)]
struct Shared {
    config: GatewayConfig,
    state: Mutex<State>,
    mo_ready: Notify,
    ring_changed: Notify,
}

/// A running emulated gateway (cloneable: every clone is the same gateway).
#[derive(Debug, Clone)]
pub struct Gateway {
    shared: Arc<Shared>,
}

/// The running gateway's tasks; stopping it ends them.
#[derive(Debug)]
pub struct GatewayHandle {
    /// The gateway.
    pub gateway: Gateway,
    /// Where its DirectIP MT listener is.
    pub mt_addr: SocketAddr,
    tasks: Vec<JoinHandle<()>>,
}

impl GatewayHandle {
    /// Stops the gateway's tasks.
    pub async fn stop(self) {
        for t in &self.tasks {
            t.abort();
        }
        for t in self.tasks {
            let _ = t.await;
        }
    }
}

fn unix_seconds() -> u32 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs() as u32)
}

impl Gateway {
    /// Starts a gateway: binds its MT listener, starts MO delivery and
    /// ring alerts. Must be called within a Tokio runtime.
    pub async fn start(config: GatewayConfig) -> std::io::Result<GatewayHandle> {
        if let Some(webhook) = &config.mo_webhook {
            webhook.signer().map_err(|e| {
                std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("JWT key: {e}"))
            })?;
        }
        let listener = TcpListener::bind(config.mt_bind).await?;
        let mt_addr = listener.local_addr()?;
        let gateway = Gateway {
            shared: Arc::new(Shared {
                config,
                state: Mutex::new(State::default()),
                mo_ready: Notify::new(),
                ring_changed: Notify::new(),
            }),
        };
        let tasks = vec![
            tokio::spawn(gateway.clone().serve_mt(listener)),
            tokio::spawn(gateway.clone().deliver_mo()),
            tokio::spawn(gateway.clone().ring_alerts()),
        ];
        Ok(GatewayHandle {
            gateway,
            mt_addr,
            tasks,
        })
    }

    fn state(&self) -> std::sync::MutexGuard<'_, State> {
        // A panicking holder leaves counters only: go on with them.
        self.shared.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// What the gateway did so far.
    pub fn log(&self) -> GatewayLog {
        self.state().log.clone()
    }

    /// MO messages waiting for the shore.
    pub fn mo_waiting(&self) -> usize {
        self.state().mo_out.len()
    }

    /// Whether a transceiver of `imei` has joined.
    pub fn knows(&self, imei: &str) -> bool {
        self.state().modems.contains_key(imei)
    }

    /// The largest MT payload taken.
    pub fn mt_limit(&self) -> usize {
        self.shared.config.mt_limit
    }

    /// Where a call to `number` is connected: the shore's RUDICS server
    /// (every number reaches it), or `None`.
    pub fn rudics_destination(&self, _number: &str) -> Option<SocketAddr> {
        self.shared.config.rudics_shore
    }

    /// How long a call takes to connect.
    pub fn dial_time(&self) -> Duration {
        self.shared.config.dial_time
    }

    /// MT messages queued for `imei`.
    pub fn mt_queued(&self, imei: &str) -> usize {
        self.state().modems.get(imei).map_or(0, |m| m.queue.len())
    }

    /// Refuse MT messages (confirmation status -6, resources unavailable)
    /// while `refusing`.
    pub fn set_refusing(&self, refusing: bool) {
        self.state().refusing = refusing;
    }

    /// A transceiver of `imei` joins; ring alerts for it come on the
    /// receiver returned (a transceiver joining again replaces the last).
    pub fn register(&self, imei: &str) -> mpsc::UnboundedReceiver<()> {
        let (tx, rx) = mpsc::unbounded_channel();
        let mut state = self.state();
        let modem = state
            .modems
            .entry(imei.to_string())
            .or_insert_with(|| Modem {
                rings: tx.clone(),
                queue: VecDeque::new(),
                next_mtmsn: 1,
                rings_left: 0,
                next_ring: None,
            });
        modem.rings = tx;
        if !modem.queue.is_empty() {
            modem.rings_left = self.shared.config.ring_count;
            modem.next_ring = Some(Instant::now());
        }
        drop(state);
        self.shared.ring_changed.notify_one();
        rx
    }

    /// The gateway's part of a session of `imei`: takes `mo` (queued for
    /// the shore), gives the first MT message queued.
    pub fn session(&self, imei: &str, mo: Option<Vec<u8>>, momsn: u16) -> GatewaySession {
        self.session_with(imei, mo, momsn, true)
    }

    /// A session whose answer will not reach the transceiver (it tells its
    /// host MO status 18): `mo` is taken and delivered all the same, no MT
    /// message is given.
    pub fn session_answer_lost(
        &self,
        imei: &str,
        mo: Option<Vec<u8>>,
        momsn: u16,
    ) -> GatewaySession {
        self.session_with(imei, mo, momsn, false)
    }

    fn session_with(
        &self,
        imei: &str,
        mo: Option<Vec<u8>>,
        momsn: u16,
        give_mt: bool,
    ) -> GatewaySession {
        let mut state = self.state();
        let (mt, queued) = match state.modems.get_mut(imei) {
            Some(m) => {
                let mt = if give_mt { m.queue.pop_front() } else { None };
                if m.queue.is_empty() {
                    m.rings_left = 0;
                    m.next_ring = None;
                }
                (mt, m.queue.len())
            }
            None => (None, 0),
        };
        if mt.is_some() {
            state.log.mt_delivered += 1;
        }
        if let Some(payload) = mo {
            state.cdr = state.cdr.wrapping_add(1);
            let header = MoHeader {
                cdr_reference: state.cdr,
                imei: imei.to_string(),
                session_status: 0,
                momsn,
                mtmsn: mt.as_ref().map_or(0, |(_, n)| *n),
                time_of_session: unix_seconds(),
            };
            state.mo_out.push_back(MoMessage {
                header,
                payload: Some(payload),
                location: self.shared.config.location,
            });
            state.log.mo_received += 1;
            self.shared.mo_ready.notify_one();
        }
        GatewaySession {
            mt,
            queued: queued.min(usize::from(u16::MAX)) as u16,
        }
    }

    /// An MT message from the shore: queued, or refused.
    pub fn take_mt(&self, mt: &MtMessage) -> MtConfirmation {
        let config = &self.shared.config;
        let mut state = self.state();
        state.auto_id = state.auto_id.wrapping_add(1);
        let auto_id = state.auto_id;
        let refusing = state.refusing;
        let status = if !directip::valid_imei(&mt.imei) {
            mt_status::INVALID_IMEI
        } else if let Some(modem) = state.modems.get_mut(&mt.imei) {
            if mt.disposition_flags & disposition::FLUSH_MT_QUEUE != 0 {
                modem.queue.clear();
            }
            match &mt.payload {
                _ if refusing => mt_status::RESOURCES_UNAVAILABLE,
                Some(p) if p.is_empty() => mt_status::PAYLOAD_EXPECTED,
                Some(p) if p.len() > config.mt_limit => mt_status::PAYLOAD_TOO_LARGE,
                Some(_) if modem.queue.len() >= MT_QUEUE_LIMIT => mt_status::QUEUE_FULL,
                Some(p) => {
                    let mtmsn = modem.next_mtmsn;
                    modem.next_mtmsn = modem.next_mtmsn.checked_add(1).unwrap_or(1);
                    modem.queue.push_back((p.clone(), mtmsn));
                    modem.rings_left = config.ring_count;
                    modem.next_ring = Some(Instant::now());
                    modem.queue.len() as i16
                }
                None if mt.disposition_flags & disposition::SEND_RING_ALERT != 0 => {
                    modem.rings_left = config.ring_count.max(1);
                    modem.next_ring = Some(Instant::now());
                    0
                }
                None if mt.disposition_flags & disposition::FLUSH_MT_QUEUE != 0 => 0,
                None => mt_status::PAYLOAD_EXPECTED,
            }
        } else {
            mt_status::UNKNOWN_IMEI
        };
        if status > 0 {
            state.log.mt_accepted += 1;
        } else if status < 0 {
            state.log.mt_refused.push(status);
        }
        drop(state);
        self.shared.ring_changed.notify_one();
        MtConfirmation {
            client_id: mt.client_id,
            imei: mt.imei.clone(),
            auto_id,
            status,
        }
    }

    async fn serve_mt(self, listener: TcpListener) {
        loop {
            let Ok((stream, _)) = listener.accept().await else {
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            };
            let gateway = self.clone();
            tokio::spawn(async move {
                let _ =
                    tokio::time::timeout(CONNECTION_TIMEOUT, gateway.mt_connection(stream)).await;
            });
        }
    }

    async fn mt_connection(&self, mut stream: TcpStream) -> std::io::Result<()> {
        let bytes = directip::read_message(&mut stream).await?;
        let confirmation = match MtMessage::decode(&bytes) {
            Ok(mt) => self.take_mt(&mt),
            Err(_) => {
                self.state().log.mt_refused.push(mt_status::PROTOCOL_ERROR);
                MtConfirmation {
                    client_id: 0,
                    imei: "000000000000000".into(),
                    auto_id: 0,
                    status: mt_status::PROTOCOL_ERROR,
                }
            }
        };
        stream.write_all(&confirmation.encode()).await?;
        stream.shutdown().await
    }

    async fn deliver_mo(self) {
        let webhook = self
            .shared
            .config
            .mo_webhook
            .as_ref()
            .map(|w| (w, w.signer()));
        let mut wait = self.shared.config.mo_retry;
        loop {
            let next = self.state().mo_out.front().cloned();
            let Some(mo) = next else {
                self.shared.mo_ready.notified().await;
                continue;
            };
            let outcome = match (&webhook, self.shared.config.mo_destination) {
                (Some((target, signer)), _) => {
                    // The key was checked at start.
                    let signer = signer.as_ref().ok().and_then(Option::as_ref);
                    target.post(&mo, signer).await
                }
                (None, Some(dest)) => {
                    let delivered = tokio::time::timeout(CONNECTION_TIMEOUT, async {
                        let mut stream = TcpStream::connect(dest).await?;
                        stream.write_all(&mo.encode()).await?;
                        stream.shutdown().await
                    })
                    .await;
                    match delivered {
                        Ok(Ok(())) => Ok(()),
                        _ => Err(None),
                    }
                }
                (None, None) => {
                    self.shared.mo_ready.notified().await;
                    continue;
                }
            };
            {
                let mut state = self.state();
                match outcome {
                    Ok(()) => {
                        state.mo_out.pop_front();
                        state.log.mo_delivered += 1;
                    }
                    Err(status) => {
                        state.log.mo_delivery_failures += 1;
                        state.log.mo_refused.extend(status);
                    }
                }
            }
            if matches!(outcome, Ok(())) {
                wait = self.shared.config.mo_retry;
            } else {
                tokio::time::sleep(wait).await;
                if let Some((target, _)) = &webhook {
                    wait = (wait * 2).min(target.max_retry.max(self.shared.config.mo_retry));
                }
            }
        }
    }

    async fn ring_alerts(self) {
        loop {
            let now = Instant::now();
            let mut next: Option<Instant> = None;
            {
                let mut state = self.state();
                let mut rung = 0;
                for modem in state.modems.values_mut() {
                    let Some(at) = modem.next_ring else { continue };
                    if modem.rings_left == 0 {
                        modem.next_ring = None;
                        continue;
                    }
                    if at <= now {
                        let _ = modem.rings.send(());
                        rung += 1;
                        modem.rings_left -= 1;
                        modem.next_ring =
                            (modem.rings_left > 0).then(|| now + self.shared.config.ring_repeat);
                    }
                    if let Some(at) = modem.next_ring {
                        next = Some(next.map_or(at, |n| n.min(at)));
                    }
                }
                state.log.rings += rung;
            }
            let wait = async {
                match next {
                    Some(at) => tokio::time::sleep_until(at).await,
                    None => std::future::pending().await,
                }
            };
            tokio::select! {
                () = wait => {}
                () = self.shared.ring_changed.notified() => {}
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn mt_messages_are_confirmed_queued_rung_and_given_in_sessions() {
        let handle = Gateway::start(GatewayConfig::default()).await.unwrap();
        let g = handle.gateway.clone();
        let imei = "300234010753370";
        let mut rings = g.register(imei);
        let send = |payload: Option<Vec<u8>>, imei: &str, flags: u16| {
            let mt = MtMessage {
                client_id: 5,
                imei: imei.to_string(),
                disposition_flags: flags,
                payload,
            };
            let addr = handle.mt_addr;
            async move {
                let mut s = TcpStream::connect(addr).await.unwrap();
                s.write_all(&mt.encode()).await.unwrap();
                let bytes = directip::read_message(&mut s).await.unwrap();
                MtConfirmation::decode(&bytes).unwrap()
            }
        };
        let c = send(Some(b"one".to_vec()), imei, 0).await;
        assert_eq!((c.status, c.client_id), (1, 5));
        assert_eq!(send(Some(b"two".to_vec()), imei, 0).await.status, 2);
        tokio::time::timeout(Duration::from_secs(5), rings.recv())
            .await
            .unwrap()
            .unwrap();
        assert_eq!(
            send(Some(vec![0; 271]), imei, 0).await.status,
            mt_status::PAYLOAD_TOO_LARGE
        );
        assert_eq!(
            send(Some(b"x".to_vec()), "300234010753371", 0).await.status,
            mt_status::UNKNOWN_IMEI
        );
        assert_eq!(
            send(Some(b"x".to_vec()), "30023401075337x", 0).await.status,
            mt_status::INVALID_IMEI
        );
        g.set_refusing(true);
        assert_eq!(
            send(Some(b"x".to_vec()), imei, 0).await.status,
            mt_status::RESOURCES_UNAVAILABLE
        );
        g.set_refusing(false);
        let s = g.session(imei, Some(b"mo".to_vec()), 3);
        assert_eq!(s.mt, Some((b"one".to_vec(), 1)));
        assert_eq!(s.queued, 1);
        assert_eq!(g.session(imei, None, 4).mt, Some((b"two".to_vec(), 2)));
        assert_eq!(g.session(imei, None, 4), GatewaySession::default());
        assert_eq!(g.mo_waiting(), 1, "no shore: the MO message is kept");
        let log = g.log();
        assert_eq!(
            (log.mt_accepted, log.mt_delivered, log.mo_received),
            (2, 2, 1)
        );
        handle.stop().await;
    }

    #[tokio::test]
    async fn mo_messages_wait_for_a_shore_that_is_down() {
        // A port that refuses connections: bound, then closed.
        let shore = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = shore.local_addr().unwrap();
        drop(shore);
        let handle = Gateway::start(GatewayConfig {
            mo_destination: Some(addr),
            mo_retry: Duration::from_millis(50),
            ..Default::default()
        })
        .await
        .unwrap();
        let g = handle.gateway.clone();
        g.register("300234010753370");
        g.session("300234010753370", Some(b"first".to_vec()), 0);
        g.session("300234010753370", Some(b"second".to_vec()), 1);
        tokio::time::sleep(Duration::from_millis(300)).await;
        assert!(g.log().mo_delivery_failures >= 2);
        assert_eq!(g.mo_waiting(), 2);
        let shore = TcpListener::bind(addr).await.unwrap();
        let mut got = Vec::new();
        for _ in 0..2 {
            let (mut s, _) = tokio::time::timeout(Duration::from_secs(5), shore.accept())
                .await
                .unwrap()
                .unwrap();
            let bytes = directip::read_message(&mut s).await.unwrap();
            got.push(MoMessage::decode(&bytes).unwrap());
        }
        assert_eq!(got[0].payload.as_deref(), Some(&b"first"[..]));
        assert_eq!(got[1].payload.as_deref(), Some(&b"second"[..]));
        assert_eq!((got[0].header.momsn, got[1].header.momsn), (0, 1));
        handle.stop().await;
    }
}
