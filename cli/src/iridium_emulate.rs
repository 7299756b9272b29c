//! `goby modem emulate-iridium`: emulated Iridium 9603 transceivers on
//! pseudo-terminals and the emulated gateway they reach, with DirectIP
//! towards a shore station, or the emulated RockBLOCK web service
//! (`--rockblock-webhook`).
//!
//! Prints one line per transceiver, `transceiver IMEI: PATH` (a vehicle's
//! Iridium driver opens PATH as its serial port), then
//! `gateway: MO to HOST:PORT, MT on ADDR` (the shore's DirectIP MO
//! listener it delivers to, and its own DirectIP MT listener), or with
//! RockBLOCK `rockblock: MO to URL, MT on URL` (the shore's webhook, and
//! the service's MT endpoint). What the
//! transceivers and the gateway do (sessions and their status, ring
//! alerts, MO messages waiting for a shore that is down, MT refusals) is
//! told on standard error as it happens.

use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use clap::Args;
use emulators::iridium::gateway::{Gateway, GatewayConfig, GatewayLog};
use emulators::iridium::radio::RadioConfig;
use emulators::iridium::rockblock::{
    RockblockLog, RockblockService, RockblockServiceConfig, WebhookTarget,
};
use emulators::iridium::transceiver::{TransceiverConfig, TransceiverLog};
use emulators::iridium::{self as emulator, TransceiverHandle, TransceiverPort};
use modemdriver::iridium::directip::{self, mt_status};
use modemdriver::iridium::rockblock::http::HttpUrl;
use modemdriver::iridium::rockblock::MoFormat;
use modemdriver::iridium::status::MoStatus;

use crate::{CliError, Status};

/// Options of `goby modem emulate-iridium`.
#[derive(Debug, Args)]
pub struct EmulateIridiumArgs {
    /// IMEI of an emulated transceiver (15 digits); repeat for several.
    #[arg(long = "imei", default_value = "300234010753370", value_name = "IMEI")]
    pub imeis: Vec<String>,
    /// Keep a symbolic link at PATH to each transceiver's pseudo-terminal
    /// (in the order of --imei).
    #[arg(long = "link", value_name = "PATH")]
    pub links: Vec<PathBuf>,
    /// The shore's DirectIP MO listener, where the gateway delivers MO
    /// messages (Goby3's default port is 40001).
    #[arg(long, default_value = "127.0.0.1:40001", value_name = "HOST:PORT")]
    pub mo_directip: SocketAddr,
    /// Where the gateway's DirectIP MT listener binds (port 0: any free).
    #[arg(long, default_value = "127.0.0.1:40002", value_name = "ADDR:PORT")]
    pub mt_directip: SocketAddr,
    /// Seconds a session takes (a real one takes 10 to 30).
    #[arg(long, default_value_t = 2.0)]
    pub session_seconds: f64,
    /// Probability that a session with service fails (MO status 10, 13,
    /// 17, 18 or 19).
    #[arg(long, default_value_t = 0.0)]
    pub session_failure: f64,
    /// Probability that a session whose MO message the gateway took is
    /// reported failed all the same (MO status 18), as Iridium sometimes
    /// does: the host sends the same message again under the same MOMSN,
    /// and the gateway delivers it again.
    #[arg(long, default_value_t = 0.0)]
    pub answer_lost: f64,
    /// Seconds between changes of the signal strength (0: a steady 5 bars).
    #[arg(long, default_value_t = 0.0)]
    pub signal_change_seconds: f64,
    /// Probability, at each change of the signal, that an outage (no
    /// signal, no service) begins.
    #[arg(long, default_value_t = 0.0)]
    pub outage_probability: f64,
    /// Shortest and longest outage, in seconds.
    #[arg(long, default_value = "60,300", value_name = "MIN,MAX")]
    pub outage_seconds: String,
    /// Largest MT payload the gateway takes (270 bytes for a 9602/9603).
    #[arg(long, default_value_t = 270)]
    pub mt_limit: usize,
    /// Seconds between ring alerts while MT messages wait.
    #[arg(long, default_value_t = 20.0)]
    pub ring_repeat_seconds: f64,
    /// Seed of the failures and of the sky.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Be the RockBLOCK web service: post MO messages to the shore's
    /// webhook at URL (e.g. http://127.0.0.1:8080/), each with a JWT,
    /// instead of DirectIP; take MT messages on --rockblock-mt.
    #[arg(long, value_name = "URL")]
    pub rockblock_webhook: Option<String>,
    /// Where the emulated service's MT endpoint (POST /rockblock/MT) binds.
    #[arg(long, default_value = "127.0.0.1:8081", value_name = "ADDR:PORT")]
    pub rockblock_mt: SocketAddr,
    /// The RockBLOCK account's user name the MT endpoint takes.
    #[arg(long, default_value = "user")]
    pub rockblock_username: String,
    /// The account's password.
    #[arg(long, default_value = "pass")]
    pub rockblock_password: String,
    /// The webhook posts' format: json (HTTP_JSON) or form (HTTP_POST).
    #[arg(long, default_value = "json", value_name = "json|form")]
    pub rockblock_format: String,
    /// PEM file of the RSA private key signing the posts' JWT (default:
    /// the emulator's published TEST-ONLY key, whose public key is
    /// gobyd/config/rockblock-emulator-TEST-ONLY-public-key.pem).
    #[arg(long, value_name = "FILE")]
    pub jwt_private_key: Option<PathBuf>,
    /// Post without a JWT (as Goby3's simulator does).
    #[arg(long)]
    pub rockblock_unsigned: bool,
    /// Probability that an MT POST is answered FAILED,99 (System Error).
    #[arg(long, default_value_t = 0.0)]
    pub rockblock_failure: f64,
    /// Emulate voice-enabled transceivers (a 9523: SBD limits of 1960/1890
    /// bytes, and RUDICS calls with ATD) rather than 9603s.
    #[arg(long)]
    pub voice: bool,
    /// The shore's RUDICS server (its rudics_server_port), where the
    /// gateway connects every call a voice-enabled transceiver dials
    /// (default: calls are answered NO ANSWER).
    #[arg(long, value_name = "HOST:PORT")]
    pub rudics_shore: Option<SocketAddr>,
    /// Seconds a call takes to connect (a real one: 10 to 20).
    #[arg(long, default_value_t = 1.0)]
    pub dial_seconds: f64,
    /// Drop every call this many seconds after it connects (NO CARRIER).
    #[arg(long, value_name = "SECONDS")]
    pub call_drop_seconds: Option<f64>,
    /// Drop every call once it has carried this many bytes (both ways).
    #[arg(long, value_name = "BYTES")]
    pub call_drop_bytes: Option<u64>,
    /// Stop after this many seconds (default: run until interrupted).
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
}

fn seconds(value: f64, option: &str, zero_ok: bool) -> Result<Duration, CliError> {
    Duration::try_from_secs_f64(value)
        .ok()
        .filter(|d| zero_ok || !d.is_zero())
        .ok_or_else(|| {
            CliError::setup(format!(
                "{option} must be a {}number of seconds, not {value}",
                if zero_ok { "" } else { "positive " }
            ))
        })
}

fn probability(value: f64, option: &str) -> Result<f64, CliError> {
    if (0.0..=1.0).contains(&value) {
        Ok(value)
    } else {
        Err(CliError::setup(format!(
            "{option} must be a probability from 0 to 1, not {value}"
        )))
    }
}

/// The settings of the transceivers and the gateway, checked.
fn configs(args: &EmulateIridiumArgs) -> Result<(Vec<TransceiverConfig>, GatewayConfig), CliError> {
    for imei in &args.imeis {
        if !directip::valid_imei(imei) {
            return Err(CliError::setup(format!(
                "--imei {imei:?} is not an IMEI (15 digits)"
            )));
        }
    }
    if args.links.len() > args.imeis.len() {
        return Err(CliError::setup(format!(
            "{} --link for {} --imei: one link per transceiver at most",
            args.links.len(),
            args.imeis.len()
        )));
    }
    let (lo, hi) = args
        .outage_seconds
        .split_once(',')
        .and_then(|(a, b)| Some((a.trim().parse::<f64>().ok()?, b.trim().parse::<f64>().ok()?)))
        .filter(|(a, b)| a <= b)
        .ok_or_else(|| {
            CliError::setup(format!(
                "--outage-seconds {:?} is not MIN,MAX (seconds, MIN at most MAX)",
                args.outage_seconds
            ))
        })?;
    let radio = RadioConfig {
        seed: args.seed,
        change_every: seconds(args.signal_change_seconds, "--signal-change-seconds", true)?,
        outage_probability: probability(args.outage_probability, "--outage-probability")?,
        outage: (
            seconds(lo, "--outage-seconds", true)?,
            seconds(hi, "--outage-seconds", true)?,
        ),
        min_bars: 1,
    };
    let session_time = seconds(args.session_seconds, "--session-seconds", false)?;
    let session_failure = probability(args.session_failure, "--session-failure")?;
    let answer_lost = probability(args.answer_lost, "--answer-lost")?;
    let call_drop_after = args
        .call_drop_seconds
        .map(|d| seconds(d, "--call-drop-seconds", false))
        .transpose()?;
    if args.call_drop_bytes == Some(0) {
        return Err(CliError::setup("--call-drop-bytes must be above 0"));
    }
    let device = if args.voice {
        protos::goby::acomms::protobuf::IridiumDeviceType::DeviceVoiceEnabledIsu
    } else {
        protos::goby::acomms::protobuf::IridiumDeviceType::DeviceIridium96029603
    };
    let transceivers = args
        .imeis
        .iter()
        .enumerate()
        .map(|(i, imei)| TransceiverConfig {
            session_time,
            no_service_time: session_time.min(Duration::from_secs(2)) / 4,
            radio: RadioConfig {
                seed: args.seed.wrapping_add(i as u64),
                ..radio.clone()
            },
            session_failure,
            answer_lost,
            seed: args.seed.wrapping_add(1000 + i as u64),
            device,
            call_drop_after,
            call_drop_bytes: args.call_drop_bytes,
            ..TransceiverConfig::new(imei)
        })
        .collect();
    if args.mt_limit == 0 {
        return Err(CliError::setup("--mt-limit must be above 0"));
    }
    let gateway = GatewayConfig {
        mo_destination: Some(args.mo_directip),
        mo_webhook: webhook(args)?,
        mt_bind: args.mt_directip,
        mt_limit: args.mt_limit,
        ring_repeat: seconds(args.ring_repeat_seconds, "--ring-repeat-seconds", false)?,
        rudics_shore: args.rudics_shore,
        dial_time: seconds(args.dial_seconds, "--dial-seconds", true)?,
        ..GatewayConfig::default()
    };
    Ok((transceivers, gateway))
}

/// The shore's webhook, with --rockblock-webhook.
fn webhook(args: &EmulateIridiumArgs) -> Result<Option<WebhookTarget>, CliError> {
    let Some(url) = &args.rockblock_webhook else {
        return Ok(None);
    };
    let url = HttpUrl::parse(url, "")
        .map_err(|e| CliError::setup(format!("--rockblock-webhook: {e}")))?;
    let mut target = WebhookTarget::new(url);
    target.format = match args.rockblock_format.as_str() {
        "json" => MoFormat::Json,
        "form" => MoFormat::Form,
        other => {
            return Err(CliError::setup(format!(
                "--rockblock-format {other:?}: json or form"
            )))
        }
    };
    if args.rockblock_unsigned {
        target.signing_key_pem = None;
    } else if let Some(path) = &args.jwt_private_key {
        let pem = std::fs::read_to_string(path)
            .map_err(|e| CliError::setup(format!("--jwt-private-key {}: {e}", path.display())))?;
        target.signing_key_pem = Some(pem);
    }
    target
        .signer()
        .map_err(|e| CliError::setup(format!("--jwt-private-key: {e}")))?;
    Ok(Some(target))
}

/// Tells on stderr what the transceivers and the gateway did since the
/// last look. Never completes.
async fn report(
    imeis: &[String],
    transceivers: &[TransceiverHandle],
    gateway: &Gateway,
    rockblock: Option<&RockblockService>,
) {
    let mut seen: Vec<TransceiverLog> = vec![TransceiverLog::default(); transceivers.len()];
    let mut seen_gateway = GatewayLog::default();
    let mut seen_rockblock = RockblockLog::default();
    let (mo_way, shore_end) = if rockblock.is_some() {
        (
            "posted to the RockBLOCK webhook",
            "the shore's RockBLOCK webhook",
        )
    } else {
        (
            "delivered over DirectIP",
            "the shore's DirectIP MO listener",
        )
    };
    let mut shore_down = false;
    let mut tick = tokio::time::interval(Duration::from_millis(200));
    loop {
        tick.tick().await;
        for ((t, seen), imei) in transceivers.iter().zip(&mut seen).zip(imeis) {
            let now = t.log();
            for code in now.sessions_failed.iter().skip(seen.sessions_failed.len()) {
                eprintln!("transceiver {imei}: session failed, {}", MoStatus(*code));
            }
            if now.sessions_ok > seen.sessions_ok {
                eprintln!(
                    "transceiver {imei}: {} session(s) succeeded ({} MO sent, {} MT received in all)",
                    now.sessions_ok - seen.sessions_ok,
                    now.mo_sent,
                    now.mt_received
                );
            }
            if now.rings > seen.rings {
                eprintln!("transceiver {imei}: ring alert (SBDRING)");
            }
            if now.calls > seen.calls {
                eprintln!("transceiver {imei}: call connected ({} in all)", now.calls);
            }
            if now.calls_dropped > seen.calls_dropped {
                eprintln!(
                    "transceiver {imei}: call dropped (NO CARRIER; {} dropped in all)",
                    now.calls_dropped
                );
            }
            *seen = now;
        }
        let now = gateway.log();
        if now.mo_delivered > seen_gateway.mo_delivered {
            eprintln!(
                "gateway: {} MO message(s) {mo_way}",
                now.mo_delivered - seen_gateway.mo_delivered
            );
        }
        if now.mo_delivered > seen_gateway.mo_delivered {
            shore_down = false;
        }
        if now.mo_delivery_failures > seen_gateway.mo_delivery_failures && !shore_down {
            shore_down = true;
            eprintln!(
                "gateway: {shore_end} does not answer; {} MO message(s) wait (tried again every second{})",
                gateway.mo_waiting(),
                if rockblock.is_some() { ", then less often" } else { "" }
            );
        }
        for status in now.mo_refused.iter().skip(seen_gateway.mo_refused.len()) {
            eprintln!(
                "gateway: the shore's webhook answered HTTP {status}; the post is made again"
            );
        }
        if let Some(rb) = rockblock {
            let log = rb.log();
            for code in log.mt_refused.iter().skip(seen_rockblock.mt_refused.len()) {
                eprintln!(
                    "rockblock: MT POST refused, FAILED,{code} ({})",
                    modemdriver::iridium::rockblock::ErrorCode::from_code(*code).description()
                );
            }
            seen_rockblock = log;
        }
        if now.mt_accepted > seen_gateway.mt_accepted {
            eprintln!(
                "gateway: {} MT message(s) queued",
                now.mt_accepted - seen_gateway.mt_accepted
            );
        }
        for status in now.mt_refused.iter().skip(seen_gateway.mt_refused.len()) {
            eprintln!(
                "gateway: MT message refused, status {status} ({})",
                mt_status::meaning(*status)
            );
        }
        seen_gateway = now;
    }
}

/// Runs `goby modem emulate-iridium`.
pub fn emulate_iridium(
    args: &EmulateIridiumArgs,
    stdout: &mut dyn Write,
) -> Result<Status, CliError> {
    let (transceivers, gateway_config) = configs(args)?;
    let duration = args
        .duration
        .map(|d| seconds(d, "--duration", false))
        .transpose()?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| CliError::setup(format!("cannot start the runtime: {e}")))?;
    runtime.block_on(async {
        let end = crate::stop::run_ends(duration);
        let mo = gateway_config.mo_destination;
        let webhook_url = gateway_config.mo_webhook.as_ref().map(|w| w.url.to_string());
        let gateway = Gateway::start(gateway_config).await.map_err(|e| {
            CliError::setup(format!(
                "gateway: cannot bind the DirectIP MT listener {}: {e}",
                args.mt_directip
            ))
        })?;
        let rockblock = if args.rockblock_webhook.is_some() {
            let service = RockblockService::start(
                RockblockServiceConfig {
                    bind: args.rockblock_mt,
                    username: args.rockblock_username.clone(),
                    password: args.rockblock_password.clone(),
                    failure: probability(args.rockblock_failure, "--rockblock-failure")?,
                    seed: args.seed,
                    ..Default::default()
                },
                gateway.gateway.clone(),
            )
            .await
            .map_err(|e| {
                CliError::setup(format!(
                    "rockblock: cannot bind the MT endpoint {}: {e}",
                    args.rockblock_mt
                ))
            })?;
            Some(service)
        } else {
            None
        };
        let mut handles = Vec::new();
        for (i, config) in transceivers.into_iter().enumerate() {
            let imei = config.imei.clone();
            let port = TransceiverPort::Pty {
                link: args.links.get(i).cloned(),
            };
            let handle = emulator::start(config, port, gateway.gateway.clone())
                .map_err(|e| CliError::setup(format!("transceiver {imei}: {e}")))?;
            writeln!(stdout, "transceiver {imei}: {}", handle.path())?;
            handles.push(handle);
        }
        match (&rockblock, &webhook_url) {
            (Some(service), Some(url)) => writeln!(
                stdout,
                "rockblock: MO to {url}, MT on {}",
                service.mt_url()
            )?,
            _ => writeln!(
                stdout,
                "gateway: MO to {}, MT on {}",
                mo.map_or("nowhere".to_string(), |a| a.to_string()),
                gateway.mt_addr
            )?,
        }
        if let Some(shore) = args.rudics_shore {
            writeln!(stdout, "rudics: calls to {shore}")?;
        }
        stdout.flush()?;
        tokio::select! {
            () = end => {}
            () = report(&args.imeis, &handles, &gateway.gateway, rockblock.as_ref().map(|r| &r.service)) => {}
        }
        if let Some(r) = rockblock {
            r.stop().await;
        }
        for h in handles {
            h.stop().await;
        }
        gateway.stop().await;
        Ok(Status::Ok)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        args: EmulateIridiumArgs,
    }

    fn args_of(args: &[&str]) -> EmulateIridiumArgs {
        Cli::try_parse_from(["x"].iter().chain(args)).unwrap().args
    }

    #[test]
    fn settings_from_the_options_and_their_refusals() {
        let (t, g) = configs(&args_of(&[
            "--session-seconds",
            "0.5",
            "--imei",
            "300234010753371",
        ]))
        .unwrap();
        assert_eq!(t.len(), 1);
        assert_eq!(t[0].imei, "300234010753371");
        assert_eq!(t[0].session_time, Duration::from_millis(500));
        assert_eq!(g.mt_limit, 270);
        assert_eq!(g.mo_destination, Some("127.0.0.1:40001".parse().unwrap()));
        assert_eq!(g.mo_webhook, None);
        let (_, g) = configs(&args_of(&[
            "--rockblock-webhook",
            "http://127.0.0.1:8080/rb",
            "--rockblock-format",
            "form",
        ]))
        .unwrap();
        let w = g.mo_webhook.unwrap();
        assert_eq!(w.url.to_string(), "http://127.0.0.1:8080/rb");
        assert_eq!(w.format, MoFormat::Form);
        assert!(w.signing_key_pem.is_some());
        for (bad, says) in [
            (&["--imei", "123"][..], "not an IMEI"),
            (&["--session-failure", "1.5"], "probability"),
            (&["--outage-seconds", "9,1"], "MIN,MAX"),
            (&["--session-seconds", "0"], "positive"),
            (
                &["--link", "/tmp/a", "--link", "/tmp/b"],
                "one link per transceiver",
            ),
            (&["--rockblock-webhook", "ftp://x"], "--rockblock-webhook"),
            (
                &[
                    "--rockblock-webhook",
                    "http://127.0.0.1:8080/",
                    "--rockblock-format",
                    "xml",
                ],
                "json or form",
            ),
            (
                &[
                    "--rockblock-webhook",
                    "http://127.0.0.1:8080/",
                    "--jwt-private-key",
                    "/nonexistent.pem",
                ],
                "--jwt-private-key",
            ),
        ] {
            let e = configs(&args_of(bad)).unwrap_err().to_string();
            assert!(e.contains(says), "{bad:?}: {e}");
        }
    }
}
