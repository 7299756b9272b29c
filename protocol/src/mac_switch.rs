//! The MAC switcher's lines: the `mac_switch` request (switch to a named
//! MAC, or ask which runs), its reply, and the `mac_switch` event (topic
//! `mac`) told at every switch, renewal, lapse and refusal.
//!
//! ```text
//! {"mac_switch": {"mac": "quiet", "keep_alive_seconds": 120}}
//! {"mac_switch": {}}
//! ```

use serde::{Deserialize, Serialize};

/// `mac_switch`: switch to the MAC named `mac`, for `keep_alive_seconds`
/// unless asked for again (absent: until switched again); without `mac`,
/// only ask which MAC runs.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MacSwitchRequest {
    /// The name of the MAC to run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mac: Option<String>,
    /// Seconds it runs unless asked for again.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub keep_alive_seconds: Option<f64>,
}

/// Which MAC runs: the reply to `mac_switch`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MacSwitchState {
    /// The name of the MAC running.
    pub active: String,
    /// The name of the default MAC.
    pub default_mac: String,
    /// Every MAC's name.
    pub macs: Vec<String>,
    /// When the one running lapses, seconds since the UNIX epoch (absent:
    /// it does not).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub keep_alive_until: Option<f64>,
}

/// `{"event": "mac_switch", "mac_switch": NAME, "previous", "reason",
/// "keep_alive_until", "from", "error"}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "event", rename = "mac_switch")]
pub struct MacSwitch {
    /// The name of the MAC running after it.
    pub mac_switch: String,
    /// The name of the one that ran before.
    pub previous: String,
    /// Why: `requested`, `renewed`, `keep_alive_lapsed`, `restored`,
    /// `keep_alive_lapsed_while_down`, or `refused` (with `error`).
    pub reason: String,
    /// When the one running lapses, seconds since the UNIX epoch (absent:
    /// it does not).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub keep_alive_until: Option<f64>,
    /// Where the request came from (`moos`, `json`, `mqtt`; absent for a
    /// lapse or a restart).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from: Option<String>,
    /// Why the request was refused (absent: it was not).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The link it happened on, by its name, when the daemon has `link`
    /// sections (absent for the one link of a top-level `driver`; a
    /// `MACUpdate` or a MAC switch acts on the first link).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<String>,
}
