//! What a gateway says of its medium access control, typed: its TDMA
//! cycle (gobyd's retained MQTT `mac_cycle`, the JSON `mac_cycle` reply
//! and event), which MAC of its switcher runs (MQTT `mac_active`, the JSON
//! `mac_switch` reply and event), and the rate it chose from the link
//! (MQTT `mac_rate`, the JSON `mac_rate` event). Read leniently: a key missing takes the
//! `.proto`'s default.

use serde_json::Value;

/// One slot of a TDMA cycle (a `ModemTransmission` as gobyd's cycle gives
/// it).
#[derive(Debug, Clone, PartialEq)]
pub struct Slot {
    /// Modem id of the node initiating it (0: a quiet slot).
    pub src: i64,
    /// Modem id of its receiver (0: broadcast, -1: the first message's).
    pub dest: i64,
    /// Modem rate.
    pub rate: i64,
    /// Length, seconds.
    pub seconds: f64,
    /// Its transmission type (`DATA`, `DRIVER_SPECIFIC`, ...).
    pub kind: String,
    /// The DCCL types it may carry (scripted TDMA; empty: any).
    pub packet_types: Vec<String>,
    /// A shared slot (slotted ALOHA).
    pub shared: bool,
    /// Its rate is chosen from the link.
    pub adaptive_rate: bool,
}

impl Slot {
    /// A slot from its proto3 JSON.
    pub fn from_json(v: &Value) -> Slot {
        let number = |key: &str, default: i64| {
            v[key]
                .as_i64()
                .or_else(|| v[key].as_str().and_then(|s| s.parse().ok()))
                .unwrap_or(default)
        };
        Slot {
            src: number("src", -1),
            dest: number("dest", -1),
            rate: number("rate", 0),
            seconds: v["slot_seconds"].as_f64().unwrap_or(10.0),
            kind: v["type"].as_str().unwrap_or("DATA").to_string(),
            packet_types: v["packet_type"]
                .as_array()
                .map(|a| {
                    a.iter()
                        .filter_map(Value::as_str)
                        .map(str::to_string)
                        .collect()
                })
                .unwrap_or_default(),
            shared: v["shared"].is_object(),
            adaptive_rate: v["adaptive_rate"].as_bool().unwrap_or(false),
        }
    }
}

/// A node's TDMA cycle, as it stands or after a `MACUpdate`.
#[derive(Debug, Clone, PartialEq)]
pub struct MacCycleReport {
    /// The slots, in order.
    pub slots: Vec<Slot>,
    /// Whether the cycle runs.
    pub running: bool,
    /// Modem id of the node whose cycle it is.
    pub modem_id: Option<i64>,
    /// The update that made it (absent: the cycle as it stands).
    pub update: Option<Value>,
    /// Where the update came from: `moos`, `json`, `mqtt`, `link`, or
    /// `start` (the cycle when the bridge started), `request` (the JSON
    /// `mac_cycle` reply).
    pub from: String,
    /// Why the update was refused (the cycle unchanged).
    pub error: Option<String>,
    /// When it was said, seconds since the UNIX epoch (0: not said).
    pub time: f64,
    /// The broker's retained value, handed over on subscribing (not news:
    /// it answers no request made since).
    pub retained: bool,
}

impl MacCycleReport {
    /// The MQTT `mac_cycle` payload: the cycle (`slot`, `running`,
    /// `modem_id`) with `update`, `from`, `error`, `time`.
    pub fn from_json(v: &Value) -> MacCycleReport {
        MacCycleReport {
            slots: v["slot"]
                .as_array()
                .map(|s| s.iter().map(Slot::from_json).collect())
                .unwrap_or_default(),
            running: v["running"].as_bool().unwrap_or(true),
            modem_id: v["modem_id"].as_i64(),
            update: v.get("update").filter(|u| u.is_object()).cloned(),
            from: v["from"].as_str().unwrap_or("").to_string(),
            error: v["error"].as_str().map(str::to_string),
            time: v["time"].as_f64().unwrap_or(0.0),
            retained: false,
        }
    }
}

/// Which MAC of a node's switcher runs.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MacActiveReport {
    /// The name of the MAC running.
    pub active: String,
    /// The one that ran before (absent: not said, as in a reply).
    pub previous: Option<String>,
    /// Why it runs: `requested`, `renewed`, `keep_alive_lapsed`,
    /// `restored`, `keep_alive_lapsed_while_down`, `refused`, `started`
    /// (absent: a reply).
    pub reason: Option<String>,
    /// When it lapses to the default, seconds since the UNIX epoch.
    pub keep_alive_until: Option<f64>,
    /// Where the request came from (`moos`, `json`, `mqtt`).
    pub from: Option<String>,
    /// Why a request was refused.
    pub error: Option<String>,
    /// The default MAC (from a reply only).
    pub default_mac: Option<String>,
    /// Every MAC's name (from a reply only; empty: not said).
    pub macs: Vec<String>,
    /// When it was said, seconds since the UNIX epoch (0: not said).
    pub time: f64,
    /// The broker's retained value, handed over on subscribing.
    pub retained: bool,
}

impl MacActiveReport {
    /// The MQTT `mac_active` payload (the JSON `mac_switch` event with
    /// `time`).
    pub fn from_json(v: &Value) -> MacActiveReport {
        let text = |key: &str| v[key].as_str().map(str::to_string);
        MacActiveReport {
            active: text("mac_switch").unwrap_or_default(),
            previous: text("previous"),
            reason: text("reason"),
            keep_alive_until: v["keep_alive_until"].as_f64(),
            from: text("from"),
            error: text("error"),
            default_mac: None,
            macs: Vec::new(),
            time: v["time"].as_f64().unwrap_or(0.0),
            retained: false,
        }
    }

    /// The JSON interface's reply to `mac_switch`.
    pub fn of_state(state: &gobyd_protocol::mac_switch::MacSwitchState, time: f64) -> Self {
        MacActiveReport {
            active: state.active.clone(),
            keep_alive_until: state.keep_alive_until,
            default_mac: Some(state.default_mac.clone()),
            macs: state.macs.clone(),
            time,
            ..Default::default()
        }
    }
}

/// The rate a node chose from the link for a transmission (MQTT
/// `mac_rate`, the JSON `mac_rate` event).
#[derive(Debug, Clone, PartialEq)]
pub struct MacRateReport {
    /// The modem rate.
    pub rate: i64,
    /// The destination it was chosen for.
    pub dest: i64,
    /// The slot's index in its cycle.
    pub slot_index: i64,
    /// Why: `no_link_data`, `first`, `kept`, `up`, `down`.
    pub reason: String,
    /// The SNR it was chosen from, dB.
    pub snr: Option<f64>,
    /// The chance of losing the packet at that rate.
    pub packet_error: Option<f64>,
    /// A faster rate would do but does not fit the slot.
    pub slot_limited: bool,
    /// When, seconds since the UNIX epoch.
    pub time: f64,
}

impl MacRateReport {
    /// The MQTT `mac_rate` payload (the JSON `mac_rate` event with
    /// `time`).
    pub fn from_json(v: &Value) -> Self {
        MacRateReport {
            rate: v["mac_rate"].as_i64().unwrap_or(0),
            dest: v["dest"].as_i64().unwrap_or(-1),
            slot_index: v["slot_index"].as_i64().unwrap_or(0),
            reason: v["reason"].as_str().unwrap_or("").to_string(),
            snr: v["snr"].as_f64(),
            packet_error: v["packet_error"].as_f64(),
            slot_limited: v["slot_limited"].as_bool().unwrap_or(false),
            time: v["time"].as_f64().unwrap_or(0.0),
        }
    }

    /// The JSON `mac_rate` event, heard at `time`.
    pub fn of_event(e: &gobyd_protocol::event::MacRate, time: f64) -> Self {
        MacRateReport {
            rate: i64::from(e.mac_rate),
            dest: i64::from(e.dest),
            slot_index: i64::from(e.slot_index),
            reason: e.reason.clone(),
            snr: e.snr,
            packet_error: e.packet_error,
            slot_limited: e.slot_limited,
            time,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn a_cycle_with_its_slots_and_defaults() {
        let c = MacCycleReport::from_json(&json!({
            "slot": [{"src": 1, "dest": 0, "rate": 5, "slot_seconds": 12.5, "type": "DATA",
                      "packet_type": ["goby.example.Command"], "adaptive_rate": true},
                     {"src": 0, "shared": {"min_priority": 0.5}}],
            "running": false, "modem_id": 1, "from": "mqtt", "update": {"update_type": "ASSIGN"},
            "time": 7.5}));
        assert_eq!(c.slots.len(), 2);
        assert_eq!(c.slots[0].packet_types, ["goby.example.Command"]);
        assert!(c.slots[0].adaptive_rate && !c.slots[0].shared);
        assert_eq!(
            (c.slots[1].dest, c.slots[1].rate, c.slots[1].seconds),
            (-1, 0, 10.0)
        );
        assert!(c.slots[1].shared);
        assert_eq!((c.running, c.modem_id, c.time), (false, Some(1), 7.5));
        assert_eq!(c.from, "mqtt");
        assert!(c.update.is_some() && c.error.is_none());
    }
}
