//! A node's medium access control as the console shows it, and the
//! requests its form sends. Sans-IO.
//!
//! [`MacView`] keeps, per node, the TDMA cycle it runs (its slots: source,
//! destination, rate, length, type, packet types; whether it runs; the
//! last update and where it came from, or why it was refused), which MAC
//! of its switcher runs (name, reason of the last switch, keep-alive
//! deadline, the MACs it has when the node said) and the last rate it chose
//! from the link. [`MacRequest`] is the form's body: a Goby3
//! `goby.acomms.protobuf.MACUpdate` or a switch of the MAC switcher,
//! checked before it goes out on the node's MQTT `mac_update`/`mac_switch`
//! topic or as the JSON interface's `mac_update`/`mac_switch` request.

use gobyd_protocol::mac_switch::MacSwitchRequest;
use serde::Deserialize;
use serde_json::{json, Value};

use crate::mac_report::{MacActiveReport, MacCycleReport, MacRateReport, Slot};

/// What a MAC request from the page asks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MacKind {
    /// A `MACUpdate` of the TDMA cycle.
    Update,
    /// A switch of the MAC switcher.
    Switch,
}

impl MacKind {
    /// Its word: the MQTT topic under `PREFIX/NODE/`, the JSON request's
    /// key, and the command's type on the page (`mac_update`,
    /// `mac_switch`).
    pub fn word(self) -> &'static str {
        match self {
            MacKind::Update => "mac_update",
            MacKind::Switch => "mac_switch",
        }
    }

    /// The kind whose [`word`](Self::word) is `word`.
    pub fn of_word(word: &str) -> Option<Self> {
        [MacKind::Update, MacKind::Switch]
            .into_iter()
            .find(|k| k.word() == word)
    }
}

/// What the console knows of one node's medium access.
#[derive(Debug, Clone, Default)]
pub struct MacView {
    cycle: Option<MacCycleReport>,
    active: Option<MacActiveReport>,
    rate: Option<MacRateReport>,
}

impl MacView {
    /// The node said its cycle (a refused update's report carries the
    /// cycle unchanged, with the reason).
    pub fn take_cycle(&mut self, report: &MacCycleReport) {
        self.cycle = Some(report.clone());
    }

    /// The node said which MAC runs; the names of its MACs and its
    /// default, said only in replies, are kept across later events.
    pub fn take_active(&mut self, report: &MacActiveReport) {
        let mut next = report.clone();
        if let Some(before) = &self.active {
            if next.macs.is_empty() {
                next.macs = before.macs.clone();
            }
            if next.default_mac.is_none() {
                next.default_mac = before.default_mac.clone();
            }
        }
        self.active = Some(next);
    }

    /// The node chose a rate from the link.
    pub fn take_rate(&mut self, report: &MacRateReport) {
        self.rate = Some(report.clone());
    }

    /// The node's modem id, as its cycle says.
    pub fn modem_id(&self) -> Option<i64> {
        self.cycle.as_ref().and_then(|c| c.modem_id)
    }

    /// For the page: `{"cycle": {"slots": [{"src", "dest", "rate",
    /// "seconds", "type", "packet_types", "shared", "adaptive_rate"}],
    /// "seconds" (the cycle's length), "running", "modem_id", "from",
    /// "update", "error", "time"} | null, "active": {"name", "previous",
    /// "reason", "keep_alive_until", "from", "error", "default_mac",
    /// "macs", "time"} | null, "rate": {"rate", "dest", "slot_index",
    /// "reason", "snr", "packet_error", "slot_limited", "time"} | null}`.
    pub fn json(&self) -> Value {
        let cycle = self.cycle.as_ref().map(|c| {
            json!({
                "slots": c.slots.iter().map(slot_json).collect::<Vec<_>>(),
                "seconds": c.slots.iter().map(|s| s.seconds).sum::<f64>(),
                "running": c.running, "modem_id": c.modem_id, "from": c.from,
                "update": c.update, "error": c.error, "time": c.time,
            })
        });
        let active = self.active.as_ref().map(|a| {
            json!({
                "name": a.active, "previous": a.previous, "reason": a.reason,
                "keep_alive_until": a.keep_alive_until, "from": a.from, "error": a.error,
                "default_mac": a.default_mac, "macs": a.macs, "time": a.time,
            })
        });
        let rate = self.rate.as_ref().map(|r| {
            json!({
                "rate": r.rate, "dest": r.dest, "slot_index": r.slot_index, "reason": r.reason,
                "snr": r.snr, "packet_error": r.packet_error, "slot_limited": r.slot_limited,
                "time": r.time,
            })
        });
        json!({"cycle": cycle, "active": active, "rate": rate})
    }
}

fn slot_json(s: &Slot) -> Value {
    json!({
        "src": s.src, "dest": s.dest, "rate": s.rate, "seconds": s.seconds, "type": s.kind,
        "packet_types": s.packet_types, "shared": s.shared, "adaptive_rate": s.adaptive_rate,
    })
}

/// The body of the page's `POST /api/mac`: `{"node", "update": {…MACUpdate…}}`
/// or `{"node", "switch": {"mac", "keep_alive_seconds"}}`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MacRequest {
    /// The node whose MAC changes.
    pub node: String,
    /// A `goby.acomms.protobuf.MACUpdate` in proto3 JSON; `src` and
    /// `dest` left out are the node's own modem id.
    #[serde(default)]
    pub update: Option<Value>,
    /// A switch of the MAC switcher.
    #[serde(default)]
    pub switch: Option<Value>,
}

impl MacRequest {
    /// What goes out, checked: its kind and the JSON to send (the
    /// `MACUpdate`, or the switch), for a node whose modem id is
    /// `modem_id` (when known). The error says what is wrong, naming the
    /// field.
    pub fn prepare(&self, modem_id: Option<i64>) -> Result<(MacKind, Value), String> {
        match (&self.update, &self.switch) {
            (Some(update), None) => prepare_update(update, modem_id).map(|u| (MacKind::Update, u)),
            (None, Some(switch)) => prepare_switch(switch).map(|s| (MacKind::Switch, s)),
            _ => Err("give either \"update\" (a MACUpdate) or \"switch\" (a MAC to run)".into()),
        }
    }
}

/// A `MACUpdate` with `src` and `dest` filled in, checked as gobyd reads
/// it.
fn prepare_update(update: &Value, modem_id: Option<i64>) -> Result<Value, String> {
    let mut update = update.clone();
    let Some(fields) = update.as_object_mut() else {
        return Err("update: a MACUpdate is a JSON object".into());
    };
    for key in ["src", "dest"] {
        if !fields.contains_key(key) {
            let id = modem_id.ok_or_else(|| {
                format!("update.{key}: the node's modem id is not known yet; give {key}")
            })?;
            fields.insert(key.into(), id.into());
        }
    }
    gobyd::json::mac_update_of(update.clone())?;
    Ok(update)
}

/// A switch (`{"mac", "keep_alive_seconds"}`), checked: a name, and a
/// keep-alive that is a positive number of seconds when given.
fn prepare_switch(switch: &Value) -> Result<Value, String> {
    let request: MacSwitchRequest =
        serde_json::from_value(switch.clone()).map_err(|e| format!("switch: {e}"))?;
    match request.mac.as_deref().map(str::trim) {
        None | Some("") => return Err("switch.mac: name the MAC to run".into()),
        Some(_) => {}
    }
    if let Some(k) = request.keep_alive_seconds {
        if !(k.is_finite() && k > 0.0) {
            return Err(format!(
                "switch.keep_alive_seconds: {k} is not a positive number of seconds (leave it out for no keep-alive)"
            ));
        }
    }
    serde_json::to_value(&request).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(body: Value) -> Result<(MacKind, Value), String> {
        serde_json::from_value::<MacRequest>(body)
            .map_err(|e| e.to_string())?
            .prepare(Some(2))
    }

    #[test]
    fn an_update_gets_the_nodes_modem_id() {
        let (kind, update) = request(json!({"node": "auv2", "update": {
            "update_type": "ASSIGN", "slot": [{"src": 2, "rate": 0, "slot_seconds": 4}]}}))
        .unwrap();
        assert_eq!(kind, MacKind::Update);
        assert_eq!((&update["src"], &update["dest"]), (&json!(2), &json!(2)));
        let (_, given) =
            request(json!({"node": "auv2", "update": {"src": 1, "update_type": "CLEAR"}})).unwrap();
        assert_eq!(given["src"], 1);
    }

    #[test]
    fn bad_requests_say_what_is_wrong() {
        let said = |body: Value| request(body).unwrap_err();
        let e = said(json!({"node": "a", "update": {"update_type": "SHUFFLE"}}));
        assert!(e.contains("MACUpdate") && e.contains("SHUFFLE"), "{e}");
        let e = said(json!({"node": "a", "update": {"update_type": "ASSIGN",
            "slot": [{"slot_seconds": "long"}]}}));
        assert!(e.contains("MACUpdate"), "{e}");
        assert!(said(json!({"node": "a", "update": [1]})).contains("JSON object"));
        assert!(said(json!({"node": "a"})).contains("either"));
        assert!(said(json!({"node": "a", "update": {}, "switch": {}})).contains("either"));
        assert!(said(json!({"node": "a", "switch": {}})).contains("switch.mac"));
        let e = said(json!({"node": "a", "switch": {"mac": "quiet", "keep_alive_seconds": -3}}));
        assert!(e.contains("switch.keep_alive_seconds"), "{e}");
        assert!(said(json!({"node": "a", "switch": {"mac": "q", "loud": 1}})).contains("loud"));
        let unknown = MacRequest {
            node: "a".into(),
            update: Some(json!({"update_type": "CLEAR"})),
            switch: None,
        };
        let e = unknown.prepare(None).unwrap_err();
        assert!(e.contains("update.src") && e.contains("modem id"), "{e}");
    }

    #[test]
    fn the_view_keeps_the_names_of_the_macs_across_events() {
        let mut view = MacView::default();
        view.take_active(&MacActiveReport {
            active: "survey".into(),
            default_mac: Some("survey".into()),
            macs: vec!["survey".into(), "quiet".into()],
            ..Default::default()
        });
        view.take_active(&MacActiveReport::from_json(&json!({
            "mac_switch": "quiet", "previous": "survey", "reason": "requested",
            "keep_alive_until": 1000.5, "from": "mqtt", "time": 900})));
        let v = view.json();
        assert_eq!(v["active"]["name"], "quiet");
        assert_eq!(v["active"]["macs"], json!(["survey", "quiet"]));
        assert_eq!(v["active"]["keep_alive_until"], 1000.5);
        assert_eq!(v["cycle"], Value::Null);
    }
}
