//! The HTTP endpoint that takes RockBLOCK's MO webhook posts (axum, HTTP/1.1).
//!
//! A `POST` to the configured path is read ([`MoPost::parse`]), its token
//! checked ([`JwtVerifier`], unless verification is off), and handed on as
//! a [`WebhookEvent::Arrival`]; the service gets `200 OK` once the
//! receiver has taken it (the service delivers again what is not answered
//! with 200, so nothing is dropped on a refusal or while the shore is
//! down). A post that is refused gets 400 (unreadable), 401 (no token) or
//! 403 (a token that does not verify), and a [`WebhookEvent::Refused`] for
//! the log; other paths 404, other methods 405. Nothing a client sends
//! panics the endpoint.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use axum::body::Bytes;
use axum::extract::{ConnectInfo, DefaultBodyLimit, State};
use axum::http::{header::CONTENT_TYPE, HeaderMap, StatusCode};
use axum::routing::post;
use axum::Router;
use tokio::net::TcpListener;
use tokio::sync::{mpsc, oneshot};

use super::mo::{JwtVerifier, MoPost, MoRefusal};

/// Largest post body taken (a message of 1960 bytes in hex, its token and
/// the other fields fit many times over).
pub const MAX_BODY_BYTES: usize = 64 * 1024;

/// What the endpoint tells its receiver.
#[derive(Debug)]
pub enum WebhookEvent {
    /// A post taken: answer `taken` once it is handed on (the service is
    /// answered 200 then; dropping `taken` answers 503, and the service
    /// delivers it again).
    Arrival {
        /// The post.
        post: MoPost,
        /// Its body as received.
        body: Vec<u8>,
        /// Who posted it.
        peer: SocketAddr,
        /// Answer when handed on.
        taken: oneshot::Sender<()>,
    },
    /// A post refused, and why.
    Refused {
        /// Who posted it.
        peer: SocketAddr,
        /// The HTTP status answered.
        status: u16,
        /// Why.
        reason: MoRefusal,
    },
}

/// Settings of the endpoint.
#[derive(Debug, Clone)]
pub struct WebhookConfig {
    /// The path posts come to (`/` unless set).
    pub path: String,
    /// The service's key; `None`: tokens are not checked.
    pub verifier: Option<Arc<JwtVerifier>>,
    /// Longest the receiver may take to hand a post on before the service
    /// is answered 503 (the service gives up on an answer after 3 s).
    pub answer_within: Duration,
}

struct Shared {
    config: WebhookConfig,
    events: mpsc::UnboundedSender<WebhookEvent>,
}

/// The endpoint's router (for tests and for serving on a listener).
pub fn router(config: WebhookConfig, events: mpsc::UnboundedSender<WebhookEvent>) -> Router {
    let path = if config.path.starts_with('/') {
        config.path.clone()
    } else {
        format!("/{}", config.path)
    };
    Router::new()
        .route(&path, post(take))
        .layer(DefaultBodyLimit::max(MAX_BODY_BYTES))
        .with_state(Arc::new(Shared { config, events }))
}

/// Serves the endpoint on `listener` until the task is dropped or aborted.
pub async fn serve(
    listener: TcpListener,
    config: WebhookConfig,
    events: mpsc::UnboundedSender<WebhookEvent>,
) -> std::io::Result<()> {
    axum::serve(
        listener,
        router(config, events).into_make_service_with_connect_info::<SocketAddr>(),
    )
    .await
}

async fn take(
    State(shared): State<Arc<Shared>>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    headers: HeaderMap,
    body: Bytes,
) -> (StatusCode, &'static str) {
    let content_type = headers.get(CONTENT_TYPE).and_then(|v| v.to_str().ok());
    let checked = MoPost::parse(content_type, &body).and_then(|post| {
        if let Some(v) = &shared.config.verifier {
            v.verify(&post)?;
        }
        Ok(post)
    });
    let post = match checked {
        Ok(post) => post,
        Err(reason) => {
            let status = reason.http_status();
            let _ = shared.events.send(WebhookEvent::Refused {
                peer,
                status,
                reason,
            });
            let code = StatusCode::from_u16(status).unwrap_or(StatusCode::BAD_REQUEST);
            return (code, "refused\n");
        }
    };
    let (taken, handed) = oneshot::channel();
    let arrival = WebhookEvent::Arrival {
        post,
        body: body.to_vec(),
        peer,
        taken,
    };
    if shared.events.send(arrival).is_err() {
        return (StatusCode::SERVICE_UNAVAILABLE, "not taken\n");
    }
    match tokio::time::timeout(shared.config.answer_within, handed).await {
        Ok(Ok(())) => (StatusCode::OK, "OK\n"),
        _ => (StatusCode::SERVICE_UNAVAILABLE, "not taken\n"),
    }
}
