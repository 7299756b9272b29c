//! A gobyd event as the page's report: the lines of a node's JSON
//! interface, and the events of a replay, become the reports the broker's
//! gateways publish ([`fleet`](crate::fleet)).

use gobyd_protocol::Event;
use serde_json::{json, Value};

use crate::fleet::{LinkReport, QueueKind, QueueNotice, Report, RxReport};
use crate::mac_report::{MacActiveReport, MacCycleReport, MacRateReport};

/// The cycle of a JSON `mac_cycle` reply or event (`slot`, `running`,
/// `modem_id`), told at `now` and come `from` where it says.
pub fn cycle_report(cycle: &Value, from: &str, now: f64) -> MacCycleReport {
    MacCycleReport {
        from: from.to_string(),
        time: now,
        ..MacCycleReport::from_json(cycle)
    }
}

/// The report of an event line of gobyd's JSON interface, told at `now`
/// (seconds since the UNIX epoch); `None` for events the console does not
/// show.
pub fn event_report(event: Event, now: f64) -> Option<Report> {
    let queued = |kind, type_name, msg| {
        Report::Queued(QueueNotice {
            kind,
            type_name,
            time: now,
            msg,
        })
    };
    let report = match event {
        Event::Received(r) => Report::Rx(RxReport {
            type_name: r.received,
            src: i64::from(r.src),
            dest: i64::from(r.dest),
            time: now,
            msg: r.msg,
            link: r
                .link
                .filter(Value::is_object)
                .map(|l| LinkReport::from_json(&l)),
        }),
        Event::Ack(a) => queued(
            QueueKind::Ack {
                by: i64::from(a.by),
                frame: i64::from(a.frame),
            },
            a.ack,
            a.msg,
        ),
        Event::Expire(e) => queued(QueueKind::Expire, e.expire, e.msg),
        Event::Drop(d) => queued(QueueKind::Drop, d.drop, d.msg),
        Event::QueueSize(q) => Report::Queue {
            type_name: q.queue_size,
            size: q.size,
        },
        Event::DriverStatus(d) => Report::Driver {
            status: d.driver_status,
            detail: d.detail,
            time: now,
        },
        Event::Forecast(f) => Report::Forecast(serde_json::to_value(&f).unwrap_or_default()),
        Event::MacCycle(c) => Report::MacCycle(MacCycleReport {
            update: c.update,
            error: c.error,
            ..cycle_report(&c.mac_cycle, &c.from, now)
        }),
        Event::MacSwitch(m) => Report::MacActive(MacActiveReport {
            time: now,
            ..MacActiveReport::from_json(&serde_json::to_value(&m).unwrap_or_default())
        }),
        Event::MacRate(r) => Report::MacRate(MacRateReport::of_event(&r, now)),
        Event::ModemReceive(m) => {
            let t = &m.modem_receive;
            // Seconds since the UNIX epoch, as every time of the interface
            // (docs/json-protocol.md), not the `.proto`'s microseconds.
            let seconds = t["time"]
                .as_f64()
                .or_else(|| t["time"].as_str().and_then(|s| s.parse::<f64>().ok()));
            let mut summary = t.clone();
            summary["frames"] = t["frame"].as_array().map_or(0, Vec::len).into();
            summary["time"] = json!(seconds.unwrap_or(now));
            if summary["src"].is_null() {
                summary["src"] = json!(-1);
            }
            Report::Link(LinkReport::from_json(&summary))
        }
        _ => return None,
    };
    Some(report)
}
