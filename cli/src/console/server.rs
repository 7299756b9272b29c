//! The console's web server: the page and its assets (embedded in the
//! binary, nothing fetched from elsewhere), the fleet as JSON, the live
//! events as server-sent events, and the commander's check and send.
//!
//! | route | what |
//! | --- | --- |
//! | `GET /` | the page (`index.html`); at `/?static` it draws one snapshot and opens no event stream (a still picture, for headless screenshots) |
//! | `GET /console.js`, `/console.css`, `/favicon.svg` | its script, style and icon |
//! | `GET /api/state` | the snapshot: `source`, `connection`, `origin`, `nodes` (tracks and link series), `messages`, `commands`, `seq` |
//! | `GET /api/forms` | the commander's types: `[{"name", "id", "max_bytes", "fields": [...]}]` |
//! | `GET /api/events` | server-sent events: a `snapshot` first, then `node`, `track`, `link`, `message`, `command`, `origin`, `source`, `gone` (one JSON object each, its kind in `event`, with `seq` but for `source`) |
//! | `POST /api/check` | `{"type", "msg"}`: what the codec would do with it ([`Commander::check`](super::commander::Commander::check)) |
//! | `POST /api/send` | `{"node", "type", "msg"}`: sent; `{"command": ID}`, or `400` with `{"error"}` |
//! | `POST /api/mac` | `{"node", "update": {…MACUpdate…}}` or `{"node", "switch": {"mac", "keep_alive_seconds"}}`: sent to the node's MAC ([`MacRequest`]); `{"command": ID}`, or `400` with `{"error"}` |
//!
//! The `POST` bodies are read as JSON only with `Content-Type:
//! application/json` (axum's `Json`: 415 without it, 400 for a body that is
//! not JSON, 422 for one without the keys).

use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::State;
use axum::http::{header, StatusCode};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use futures_util::stream::{self, Stream};
use serde::Deserialize;
use serde_json::{json, Value};
use tokio::sync::broadcast::error::RecvError;

use super::hub::Hub;
use super::mac::MacRequest;

const INDEX: &str = include_str!("assets/index.html");
const SCRIPT: &str = include_str!("assets/console.js");
const STYLE: &str = include_str!("assets/console.css");
const ICON: &str = include_str!("assets/favicon.svg");

/// The router of the console over `hub`.
pub fn router(hub: Arc<Hub>) -> Router {
    Router::new()
        .route(
            "/",
            get(|| async { asset("text/html; charset=utf-8", INDEX) }),
        )
        .route(
            "/console.js",
            get(|| async { asset("text/javascript; charset=utf-8", SCRIPT) }),
        )
        .route(
            "/console.css",
            get(|| async { asset("text/css; charset=utf-8", STYLE) }),
        )
        .route(
            "/favicon.svg",
            get(|| async { asset("image/svg+xml", ICON) }),
        )
        .route("/api/state", get(state))
        .route("/api/forms", get(forms))
        .route("/api/events", get(events))
        .route("/api/check", post(check))
        .route("/api/send", post(send))
        .route("/api/mac", post(mac))
        .with_state(hub)
}

fn asset(kind: &'static str, body: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, kind),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

async fn state(State(hub): State<Arc<Hub>>) -> Json<Value> {
    Json(hub.snapshot())
}

async fn forms(State(hub): State<Arc<Hub>>) -> Json<Value> {
    Json(hub.commander.forms())
}

/// A draft of the commander.
#[derive(Debug, Deserialize)]
struct Draft {
    #[serde(rename = "type")]
    type_name: String,
    msg: Value,
    #[serde(default)]
    node: String,
}

async fn check(State(hub): State<Arc<Hub>>, Json(draft): Json<Draft>) -> Json<Value> {
    Json(hub.commander.check(&draft.type_name, &draft.msg))
}

async fn send(State(hub): State<Arc<Hub>>, Json(draft): Json<Draft>) -> Response {
    let sent = hub
        .send_command(&draft.node, &draft.type_name, &draft.msg)
        .await;
    answer(sent)
}

async fn mac(State(hub): State<Arc<Hub>>, Json(request): Json<MacRequest>) -> Response {
    answer(hub.send_mac(&request).await)
}

/// `{"command": ID}`, or status 400 with `{"error"}`.
fn answer(sent: Result<u64, String>) -> Response {
    match sent {
        Ok(id) => Json(json!({"command": id})).into_response(),
        Err(e) => (StatusCode::BAD_REQUEST, Json(json!({"error": e}))).into_response(),
    }
}

/// Where the event stream of one page stands.
enum Feed {
    /// The snapshot is to be sent.
    Start(Value, tokio::sync::broadcast::Receiver<Arc<str>>),
    /// Live events follow.
    Live(tokio::sync::broadcast::Receiver<Arc<str>>),
}

async fn events(State(hub): State<Arc<Hub>>) -> Sse<impl Stream<Item = Result<Event, Infallible>>> {
    let (snapshot, rx) = hub.subscribe();
    let feed = stream::unfold((Feed::Start(snapshot, rx), hub), |(feed, hub)| async move {
        match feed {
            Feed::Start(snapshot, rx) => {
                let event = Event::default().data(snapshot.to_string());
                Some((Ok(event), (Feed::Live(rx), hub)))
            }
            Feed::Live(mut rx) => match rx.recv().await {
                Ok(text) => {
                    let event = Event::default().data(&*text);
                    Some((Ok(event), (Feed::Live(rx), hub)))
                }
                // Fallen behind: start again from a new snapshot.
                Err(RecvError::Lagged(_)) => {
                    let (snapshot, rx) = hub.subscribe();
                    let event = Event::default().data(snapshot.to_string());
                    Some((Ok(event), (Feed::Live(rx), hub)))
                }
                Err(RecvError::Closed) => None,
            },
        }
    });
    Sse::new(feed).keep_alive(KeepAlive::new().interval(Duration::from_secs(15)))
}
