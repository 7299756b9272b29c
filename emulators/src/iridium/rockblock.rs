//! An emulated RockBLOCK web service in front of the emulated gateway: the
//! MT endpoint (`POST /rockblock/MT`) that queues messages for the
//! emulated transceivers (delivered after a ring alert and a session, as
//! the gateway's DirectIP MT messages are), and the MO webhook calls to
//! the shore ([`WebhookTarget`], used by the gateway's MO delivery), each
//! with a JWT signed by a key of the emulator's.
//!
//! The MT endpoint answers as the service documents: `OK,<mtId>`, or
//! `FAILED,<code>,<text>` for credentials other than the configured ones
//! (10), an IMEI no transceiver has (11), data not hex (14), longer than
//! the gateway's MT limit (15), or none (16), a full queue (99). Faults:
//! while [`RockblockService::set_refusing`] names a code every POST is
//! answered with it; `failure` is the probability (seeded) that a POST is
//! answered `FAILED,99,System Error` without being queued.
//!
//! The key pair the emulator signs with unless given one is published in
//! the repository (`test-key/`, [`EMULATOR_TEST_PRIVATE_KEY_PEM`]): for
//! tests only.

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use axum::body::Bytes;
use axum::extract::{RawQuery, State};
use axum::http::StatusCode;
use axum::routing::post;
use axum::Router;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tokio::net::TcpListener;
use tokio::task::JoinHandle;

use super::gateway::Gateway;
use modemdriver::iridium::directip::{mt_status, MoMessage, MtMessage};
use modemdriver::iridium::rockblock::http::{self, HttpUrl};
use modemdriver::iridium::rockblock::{
    transmit_time_text, ErrorCode, JwtSigner, MoFormat, MoPost, MtReply, MtRequest,
};

/// The emulator's RSA private key (PKCS#8 PEM), published: FOR TESTS ONLY.
pub const EMULATOR_TEST_PRIVATE_KEY_PEM: &str =
    include_str!("test-key/rockblock-emulator-TEST-ONLY-private-key.pem");

/// The public key of [`EMULATOR_TEST_PRIVATE_KEY_PEM`]: a shore station
/// verifies the emulator's posts with it (a copy is
/// `gobyd/config/rockblock-emulator-TEST-ONLY-public-key.pem`). Never
/// configure a real shore station with it.
pub const EMULATOR_TEST_PUBLIC_KEY_PEM: &str =
    include_str!("test-key/rockblock-emulator-TEST-ONLY-public-key.pem");

/// How long the shore's webhook has to answer (RockBLOCK's 3 s, with room
/// for a loaded machine).
pub const WEBHOOK_TIMEOUT: Duration = Duration::from_secs(5);

/// The shore's webhook, where the emulated service posts MO messages.
#[derive(Debug, Clone, PartialEq)]
pub struct WebhookTarget {
    /// Its URL.
    pub url: HttpUrl,
    /// Form or JSON posts.
    pub format: MoFormat,
    /// The RSA private key (PEM) signing each post's JWT; `None`: posts
    /// carry no token (as Goby3's simulator posts).
    pub signing_key_pem: Option<String>,
    /// Longest wait between posts of a message the shore did not take.
    pub max_retry: Duration,
    /// Position given with every message (degrees, CEP km).
    pub position: (f64, f64, f64),
}

impl WebhookTarget {
    /// A target at `url` posting JSON signed with the test key, retries up
    /// to a minute apart.
    pub fn new(url: HttpUrl) -> WebhookTarget {
        WebhookTarget {
            url,
            format: MoFormat::Json,
            signing_key_pem: Some(EMULATOR_TEST_PRIVATE_KEY_PEM.to_string()),
            max_retry: Duration::from_secs(60),
            position: (52.3867, 0.2938, 8.0),
        }
    }

    /// The signer of `signing_key_pem` (`Ok(None)` without one); `Err` for
    /// a key that is not an RSA private key.
    pub fn signer(&self) -> Result<Option<JwtSigner>, String> {
        self.signing_key_pem
            .as_deref()
            .map(|pem| JwtSigner::from_pem(pem.as_bytes()))
            .transpose()
    }

    /// The post of gateway MO message `mo`, as the service makes it.
    pub fn post_of(&self, mo: &MoMessage) -> MoPost {
        let (lat, lon, cep) = match mo.location {
            Some(l) => (l.latitude, l.longitude, f64::from(l.cep_radius_km)),
            None => self.position,
        };
        MoPost {
            imei: mo.header.imei.clone(),
            momsn: Some(u64::from(mo.header.momsn)),
            // A serial number of the emulator's: the IMEI's last five digits.
            serial: mo.header.imei.get(10..).and_then(|s| s.parse().ok()),
            transmit_time: Some(transmit_time_text(u64::from(mo.header.time_of_session))),
            iridium_latitude: Some(lat),
            iridium_longitude: Some(lon),
            iridium_cep: Some(cep),
            device_type: Some("ROCKBLOCK".into()),
            data: mo.payload.clone().unwrap_or_default(),
            jwt: None,
        }
    }

    /// Posts `mo` once: `Ok` when answered 200; `Err(Some(status))` for
    /// another status, `Err(None)` when the shore cannot be reached or
    /// does not answer.
    pub async fn post(
        &self,
        mo: &MoMessage,
        signer: Option<&JwtSigner>,
    ) -> Result<(), Option<u16>> {
        let mut post = self.post_of(mo);
        if let Some(signer) = signer {
            let iat = SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0, |d| d.as_secs());
            post = signer.sign(post, iat).map_err(|_| None)?;
        }
        match http::post(
            &self.url,
            self.format.content_type(),
            post.to_body(self.format),
            WEBHOOK_TIMEOUT,
        )
        .await
        {
            Ok(reply) if reply.status == 200 => Ok(()),
            Ok(reply) => Err(Some(reply.status)),
            Err(_) => Err(None),
        }
    }
}

/// Settings of the emulated service's MT endpoint.
#[derive(Debug, Clone, PartialEq)]
pub struct RockblockServiceConfig {
    /// Where the endpoint binds (port 0: any free).
    pub bind: SocketAddr,
    /// Its path.
    pub path: String,
    /// The account's user name.
    pub username: String,
    /// The account's password.
    pub password: String,
    /// Probability that a POST is answered `FAILED,99` (not queued).
    pub failure: f64,
    /// Seed of those failures.
    pub seed: u64,
}

impl Default for RockblockServiceConfig {
    fn default() -> Self {
        RockblockServiceConfig {
            bind: SocketAddr::from(([127, 0, 0, 1], 0)),
            path: "/rockblock/MT".into(),
            username: "user".into(),
            password: "pass".into(),
            failure: 0.0,
            seed: 1,
        }
    }
}

/// What the MT endpoint did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RockblockLog {
    /// MT messages queued.
    pub mt_queued: u64,
    /// POSTs refused, by error code.
    pub mt_refused: Vec<i32>,
}

struct Shared {
    config: RockblockServiceConfig,
    gateway: Gateway,
    state: Mutex<ServiceState>,
}

struct ServiceState {
    next_mt_id: u64,
    refusing: Option<ErrorCode>,
    rng: ChaCha8Rng,
    log: RockblockLog,
}

/// The running MT endpoint (cloneable: every clone is the same service).
#[derive(Clone)]
pub struct RockblockService {
    shared: Arc<Shared>,
}

impl std::fmt::Debug for RockblockService {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RockblockService")
            .field("config", &self.shared.config)
            .finish_non_exhaustive()
    }
}

/// The service and its task; stopping it ends the endpoint.
#[derive(Debug)]
pub struct RockblockHandle {
    /// The service.
    pub service: RockblockService,
    /// Where the MT endpoint listens.
    pub addr: SocketAddr,
    task: JoinHandle<()>,
}

impl RockblockHandle {
    /// The MT endpoint's URL.
    pub fn mt_url(&self) -> String {
        format!("http://{}{}", self.addr, self.service.shared.config.path)
    }

    /// Stops the endpoint.
    pub async fn stop(self) {
        self.task.abort();
        let _ = self.task.await;
    }
}

impl RockblockService {
    /// Binds the MT endpoint in front of `gateway`. Must be called within a
    /// Tokio runtime.
    pub async fn start(
        config: RockblockServiceConfig,
        gateway: Gateway,
    ) -> std::io::Result<RockblockHandle> {
        let listener = TcpListener::bind(config.bind).await?;
        let addr = listener.local_addr()?;
        let path = if config.path.starts_with('/') {
            config.path.clone()
        } else {
            format!("/{}", config.path)
        };
        let service = RockblockService {
            shared: Arc::new(Shared {
                state: Mutex::new(ServiceState {
                    next_mt_id: 4_114_651,
                    refusing: None,
                    rng: ChaCha8Rng::seed_from_u64(config.seed),
                    log: RockblockLog::default(),
                }),
                config,
                gateway,
            }),
        };
        let app = Router::new()
            .route(&path, post(mt_post))
            .with_state(service.clone());
        let task = tokio::spawn(async move {
            let _ = axum::serve(listener, app).await;
        });
        Ok(RockblockHandle {
            service,
            addr,
            task,
        })
    }

    fn state(&self) -> std::sync::MutexGuard<'_, ServiceState> {
        self.shared.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Answer every POST with `code` (`None`: answer as usual).
    pub fn set_refusing(&self, code: Option<ErrorCode>) {
        self.state().refusing = code;
    }

    /// What the endpoint did so far.
    pub fn log(&self) -> RockblockLog {
        self.state().log.clone()
    }

    /// The answer to a POST of `fields` (query and body, the body's first).
    pub fn answer(&self, fields: &[(String, String)]) -> MtReply {
        let reply = self.queue(fields);
        let mut state = self.state();
        match &reply {
            MtReply::Queued { .. } => state.log.mt_queued += 1,
            MtReply::Failed { code, .. } => state.log.mt_refused.push(code.code()),
        }
        reply
    }

    fn queue(&self, fields: &[(String, String)]) -> MtReply {
        let config = &self.shared.config;
        let gateway = &self.shared.gateway;
        {
            let mut state = self.state();
            if let Some(code) = state.refusing {
                return MtReply::failed(code);
            }
            if config.failure > 0.0 && state.rng.random_bool(config.failure.min(1.0)) {
                return MtReply::failed(ErrorCode::SystemError);
            }
        }
        let request = match MtRequest::from_fields(fields) {
            Ok(r) => r,
            // No credentials at all are invalid credentials before
            // anything else.
            Err(_) if fields.iter().all(|(k, _)| k != "username") => {
                return MtReply::failed(ErrorCode::InvalidCredentials)
            }
            Err(code) => return MtReply::failed(code),
        };
        if request.username != config.username || request.password != config.password {
            return MtReply::failed(ErrorCode::InvalidCredentials);
        }
        if !gateway.knows(&request.imei) {
            return MtReply::failed(ErrorCode::ImeiNotFound);
        }
        if request.data.len() > gateway.mt_limit() {
            return MtReply::failed(ErrorCode::DataTooLong);
        }
        let confirmation = gateway.take_mt(&MtMessage {
            client_id: 0,
            imei: request.imei.clone(),
            disposition_flags: if request.flush {
                modemdriver::iridium::directip::disposition::FLUSH_MT_QUEUE
            } else {
                0
            },
            payload: Some(request.data),
        });
        match confirmation.status {
            s if s > 0 => {
                let mut state = self.state();
                let mt_id = state.next_mt_id;
                state.next_mt_id += 1;
                MtReply::Queued { mt_id }
            }
            mt_status::UNKNOWN_IMEI | mt_status::INVALID_IMEI => {
                MtReply::failed(ErrorCode::ImeiNotFound)
            }
            mt_status::PAYLOAD_TOO_LARGE => MtReply::failed(ErrorCode::DataTooLong),
            mt_status::PAYLOAD_EXPECTED => MtReply::failed(ErrorCode::NoData),
            _ => MtReply::failed(ErrorCode::SystemError),
        }
    }
}

async fn mt_post(
    State(service): State<RockblockService>,
    RawQuery(query): RawQuery,
    body: Bytes,
) -> (StatusCode, String) {
    let mut fields: Vec<(String, String)> = serde_urlencoded::from_bytes(&body).unwrap_or_default();
    if let Some(q) = query {
        fields.extend(serde_urlencoded::from_str::<Vec<(String, String)>>(&q).unwrap_or_default());
    }
    (StatusCode::OK, service.answer(&fields).to_body())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::iridium::gateway::GatewayConfig;
    use modemdriver::iridium::rockblock::JwtVerifier;

    #[test]
    fn the_committed_public_key_verifies_the_emulators_tokens() {
        let signer = JwtSigner::from_pem(EMULATOR_TEST_PRIVATE_KEY_PEM.as_bytes()).unwrap();
        let verifier = JwtVerifier::from_pem(EMULATOR_TEST_PUBLIC_KEY_PEM.as_bytes()).unwrap();
        let target = WebhookTarget::new(HttpUrl::parse("127.0.0.1:1", "/").unwrap());
        let mo = MoMessage {
            header: modemdriver::iridium::directip::MoHeader {
                cdr_reference: 1,
                imei: "300234010753370".into(),
                session_status: 0,
                momsn: 12,
                mtmsn: 0,
                time_of_session: 1_693_888_404,
            },
            payload: Some(b"abc".to_vec()),
            location: None,
        };
        let post = signer.sign(target.post_of(&mo), 1).unwrap();
        verifier.verify(&post).unwrap();
        assert_eq!(post.transmit_time.as_deref(), Some("23-09-05 04:33:24"));
        assert_eq!(post.serial, Some(53370));
    }

    #[tokio::test]
    async fn mt_posts_are_queued_or_refused_with_the_services_codes() {
        let gateway = Gateway::start(GatewayConfig::default()).await.unwrap();
        let imei = "300234010753370";
        let _rings = gateway.gateway.register(imei);
        let service =
            RockblockService::start(RockblockServiceConfig::default(), gateway.gateway.clone())
                .await
                .unwrap();
        let url = HttpUrl::parse(&format!("http://{}", service.addr), "/rockblock/MT").unwrap();
        let post = |form: String| {
            let url = url.clone();
            async move {
                let reply = http::post(
                    &url,
                    "application/x-www-form-urlencoded",
                    form.into_bytes(),
                    Duration::from_secs(5),
                )
                .await
                .unwrap();
                assert_eq!(reply.status, 200);
                MtReply::parse(&String::from_utf8_lossy(&reply.body)).unwrap()
            }
        };
        let request = |data: Vec<u8>, password: &str| {
            MtRequest {
                imei: imei.into(),
                username: "user".into(),
                password: password.into(),
                data,
                flush: false,
            }
            .to_form()
        };
        assert!(matches!(
            post(request(b"one".to_vec(), "pass")).await,
            MtReply::Queued { .. }
        ));
        assert_eq!(gateway.gateway.mt_queued(imei), 1);
        let code = |r: MtReply| match r {
            MtReply::Failed { code, .. } => code,
            other => panic!("{other:?}"),
        };
        assert_eq!(
            code(post(request(b"x".to_vec(), "wrong")).await),
            ErrorCode::InvalidCredentials
        );
        assert_eq!(
            code(post(request(vec![0; 271], "pass")).await),
            ErrorCode::DataTooLong
        );
        assert_eq!(
            code(post("imei=300234010753371&username=user&password=pass&data=00".into()).await),
            ErrorCode::ImeiNotFound
        );
        assert_eq!(
            code(post("imei=300234010753370&username=user&password=pass&data=0".into()).await),
            ErrorCode::BadHex
        );
        assert_eq!(
            code(post("imei=300234010753370&username=user&password=pass".into()).await),
            ErrorCode::NoData
        );
        service
            .service
            .set_refusing(Some(ErrorCode::InsufficientCredit));
        assert_eq!(
            code(post(request(b"x".to_vec(), "pass")).await),
            ErrorCode::InsufficientCredit
        );
        service.service.set_refusing(None);
        // The fields in the query, as the service's own example sends them.
        let url_q = HttpUrl::parse(
            &format!("http://{}", service.addr),
            &format!("/rockblock/MT?{}", request(b"two".to_vec(), "pass")),
        )
        .unwrap();
        let reply = http::post(&url_q, "text/plain", Vec::new(), Duration::from_secs(5))
            .await
            .unwrap();
        assert!(String::from_utf8_lossy(&reply.body).starts_with("OK,"));
        assert_eq!(gateway.gateway.mt_queued(imei), 2);
        let s = gateway.gateway.session(imei, None, 0);
        assert_eq!(s.mt.map(|(p, _)| p), Some(b"one".to_vec()));
        let log = service.service.log();
        assert_eq!(log.mt_queued, 2);
        assert_eq!(log.mt_refused, vec![10, 15, 11, 14, 16, 13]);
        service.stop().await;
        gateway.stop().await;
    }
}
