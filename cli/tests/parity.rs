//! `goby dccl` where it follows the reference `dccl` tool (libdccl 4.x):
//! analyze without `-m`, the line prefix against `-m`, `-w`, and the words
//! of its errors and warnings (omit_id frames, oneof members, stale times).

mod common;

use std::time::{SystemTime, UNIX_EPOCH};

use common::*;

const NAV: &str = "protos/proto/goby/example/navigation.proto";

/// A `.proto` with a oneof, a repeated field and an `omit_id` type, in a
/// scratch directory of this test process.
fn choice_proto(name: &str) -> String {
    let dir = std::env::temp_dir().join(format!("goby-parity-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch dir");
    let path = dir.join("choice.proto");
    std::fs::write(
        &path,
        r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package t;
message Choice {
  option (dccl.msg) = { id: 10 max_bytes: 32 codec_version: 4 };
  required int32 a = 1 [(dccl.field) = { min: 0 max: 10 }];
  repeated int32 r = 2 [(dccl.field) = { min: 0 max: 10 max_repeat: 3 }];
  oneof payload {
    int32 code = 4 [(dccl.field) = { min: 0 max: 255 }];
    string note = 5 [(dccl.field).max_length = 6];
  }
}
message Hidden {
  option (dccl.msg) = { id: 100 max_bytes: 32 codec_version: 4 omit_id: true };
  required int32 a = 1 [(dccl.field) = { min: 0 max: 255 }];
}
"#,
    )
    .expect("write proto");
    path.to_str().expect("UTF-8 path").to_string()
}

#[test]
fn analyze_without_message_reports_every_type_sorted_by_name() {
    for args in [
        &["dccl", "analyze", "-f", NAV][..],
        &["dccl", "-a", "-f", NAV][..],
    ] {
        let out = goby(args, "");
        assert!(out.status.success(), "{args:?}: {}", stderr_text(&out));
        let text = stdout_text(&out);
        let command = text.find("125: goby.example.Command").expect("Command");
        let report = text
            .find("124: goby.example.NavigationReport")
            .expect("NavigationReport");
        assert!(command < report, "reference order (by name): {text}");
    }
    let out = goby(&["dccl", "analyze", "-H", "-f", NAV], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(
        stdout_text(&out),
        "goby.example.Command: 0x0a39f1091c37976f\n\
         goby.example.NavigationReport: 0xab8040257f525767\n"
    );
}

#[test]
fn encode_refuses_a_line_prefixed_with_another_type_than_the_message() {
    let input = "destination: 2 action: HOLD\n\
                 |goby.example.Command| destination: 3 action: HOLD\n\
                 |goby.example.NavigationReport| source: 1 destination: 2 time: 0 x: 1 y: 2 z: -3\n";
    let out = goby(
        &["dccl", "encode", "-f", NAV, "-m", "goby.example.Command"],
        input,
    );
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(lines(&stdout_text(&out)).len(), 2, "lines 1 and 2 encoded");
    assert!(
        stderr_text(&out).contains(
            "line 3: the line is prefixed |goby.example.NavigationReport| but -m gives \
             goby.example.Command: remove the prefix, or encode \
             goby.example.NavigationReport lines with -m goby.example.NavigationReport"
        ),
        "{}",
        stderr_text(&out)
    );

    // The reference tool's flags keep its behaviour: the line's type is encoded.
    let out = goby(
        &[
            "dccl",
            "-e",
            "-f",
            NAV,
            "-m",
            "goby.example.NavigationReport",
            "--format",
            "hex",
        ],
        "|goby.example.Command| destination: 2 action: HOLD\n",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(stdout_text(&out), "fa0200\n");
}

#[test]
fn console_width_sets_the_guard_lines_of_analyze() {
    let title = " 125: goby.example.Command {0x0a39f1091c37976f} ";
    for args in [
        &[
            "dccl",
            "-a",
            "-w",
            "70",
            "-f",
            NAV,
            "-m",
            "goby.example.Command",
        ][..],
        &[
            "dccl",
            "analyze",
            "--console_width",
            "70",
            "-f",
            NAV,
            "-m",
            "goby.example.Command",
        ][..],
    ] {
        let out = goby(args, "");
        assert!(out.status.success(), "{args:?}: {}", stderr_text(&out));
        let first = stdout_text(&out).lines().next().unwrap_or("").to_string();
        // (70 - 46) / 2 = 12 on each side, as libdccl's set_console_width.
        let guard = "=".repeat(12);
        assert_eq!(first, format!("{guard}{title}{guard}"));
    }
    // Default 60: (60 - 46) / 2 = 7; narrower than the title: no guard.
    let out = goby(&["dccl", "-a", "-f", NAV, "-m", "goby.example.Command"], "");
    let first = stdout_text(&out).lines().next().unwrap_or("").to_string();
    assert_eq!(first, format!("{}{title}{}", "=".repeat(7), "=".repeat(7)));
    let out = goby(
        &[
            "dccl",
            "-a",
            "-w",
            "10",
            "-f",
            NAV,
            "-m",
            "goby.example.Command",
        ],
        "",
    );
    let first = stdout_text(&out).lines().next().unwrap_or("").to_string();
    assert_eq!(first, title);

    let out = goby(&["dccl", "-a", "-w", "wide", "-f", NAV], "");
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr_text(&out).contains("invalid value 'wide'"));
}

#[test]
fn an_omit_id_frame_decoded_without_message_gets_a_hint() {
    let proto = choice_proto("omit");
    let out = goby(
        &["dccl", "encode", "-f", &proto, "-m", "t.Hidden"],
        "a: 200\n",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let hex = stdout_text(&out);
    assert_eq!(hex, "c8\n"); // reads as id 100
    let hint = "(a message with omit_id: true carries no id on the wire: name its type \
                with -m; loaded with omit_id: t.Hidden)";
    let out = goby(&["dccl", "decode", "-f", &proto], hex.clone());
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr_text(&out).contains(&format!("message id 100 has not been loaded {hint}")),
        "{}",
        stderr_text(&out)
    );
    let out = goby(&["dccl", "decode", "-f", &proto, "-m", "t.Hidden"], hex);
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(stdout_text(&out), "a: 200\n");
}

#[test]
fn values_sent_as_the_minimum_say_why() {
    let proto = choice_proto("oneof");
    let out = goby(
        &["dccl", "encode", "-f", &proto, "-m", "t.Choice"],
        "a: 30 r: 20 code: 300\n",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let err = stderr_text(&out);
    for want in [
        "line 1: warning: t.Choice.a: 30 is out of range [0, 10]: sent as the minimum 0 \
         (the field is required)",
        "line 1: warning: t.Choice.r[0]: 20 is out of range [0, 10]: sent as the minimum 0 \
         (an element of a repeated field has no \"not present\" value)",
        "line 1: warning: t.Choice.code: 300 is out of range [0, 255]: sent as the minimum 0 \
         (code is the member set of oneof payload, which has no \"not present\" value)",
    ] {
        assert!(err.contains(want), "{want}\nnot in\n{err}");
    }
    assert!(!err.contains(
        "code: 300 is out of range [0, 255]: sent as the minimum 0 (the field is required)"
    ));
}

fn now_secs() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .expect("clock after 1970")
        .as_secs()
}

/// The shipped example: every value is given to its field's precision, so
/// all but the time come back exactly; its fixed time cannot (the time codec
/// sends the time of day only), and encoding says so.
#[test]
fn the_example_round_trips_and_a_stale_time_is_warned_about() {
    let root = workspace_dir();
    let example = root.join("protos/examples/navigation_report.txt");
    let input = std::fs::read_to_string(&example).expect("example");
    let out = goby(
        &[
            "dccl",
            "encode",
            "-f",
            NAV,
            "-m",
            "goby.example.NavigationReport",
        ],
        input.clone(),
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let err = stderr_text(&out);
    // The example's times, and whether each is more than 12 hours from the
    // clock (the example was written on its date: then it is not warned
    // about, every other day it is).
    let times: Vec<u64> = input
        .lines()
        .map(|l| l.split_whitespace().nth(5).unwrap().parse().unwrap())
        .collect();
    let now = now_secs();
    for (i, time) in times.iter().enumerate() {
        let date = match i {
            0 => "2026-11-22 12:00:00 UTC",
            _ => "2026-11-22 12:01:00 UTC",
        };
        let warning = format!(
            "line {}: warning: goby.example.NavigationReport.time: {time} ({date}) is more \
             than 12 hours from this machine's clock: the time codec sends the time of day \
             only, and it decodes as ",
            i + 1
        );
        if time.abs_diff(now) > 12 * 3600 + 60 {
            assert!(err.contains(&warning), "{err}");
        } else if time.abs_diff(now) < 12 * 3600 - 60 {
            assert!(!err.contains(&warning), "{err}");
        }
    }
    assert_eq!(
        err.lines().count(),
        err.lines()
            .filter(|l| l.contains("warning: goby.example.NavigationReport.time: "))
            .count(),
        "only the time is warned about: {err}"
    );
    let out = goby(&["dccl", "decode", "-f", NAV], stdout_text(&out));
    assert!(out.status.success(), "{}", stderr_text(&out));
    let strip_time = |line: &str| -> String {
        line.split_whitespace()
            .collect::<Vec<_>>()
            .chunks(2)
            .filter(|kv| kv[0] != "time:")
            .map(|kv| kv.join(" "))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let decoded = stdout_text(&out);
    assert_eq!(
        lines(&decoded)
            .iter()
            .map(|l| strip_time(l))
            .collect::<Vec<_>>(),
        input.lines().map(strip_time).collect::<Vec<_>>()
    );

    // The same messages at the current time round-trip exactly, unwarned.
    let now = now_secs();
    let fresh: String = input
        .lines()
        .enumerate()
        .map(|(i, l)| {
            let stale = l.split_whitespace().nth(5).expect("time value");
            format!("{}\n", l.replace(stale, &(now + i as u64).to_string()))
        })
        .collect();
    let out = goby(
        &[
            "dccl",
            "encode",
            "-f",
            NAV,
            "-m",
            "goby.example.NavigationReport",
        ],
        fresh.clone(),
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(stderr_text(&out), "");
    let out = goby(&["dccl", "decode", "-f", NAV], stdout_text(&out));
    assert_eq!(stdout_text(&out), fresh);
}

fn lines(text: &str) -> Vec<&str> {
    text.lines().filter(|l| !l.is_empty()).collect()
}
