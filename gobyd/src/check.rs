//! The one check of a configuration, shared by `gobyd --check` and the
//! daemon's start: what it refuses the daemon never runs with, and what it
//! accepts the daemon starts with unless something only starting shows.

use std::sync::Arc;

use amac::MacManager;
use protos::goby::apps::protobuf::GobydConfig;
use queue::{Clock, QueueManager, SystemClock};

use crate::config::{self, ConfigError};
pub use crate::core::Checked;
use crate::error::DaemonError;

/// The one check of a configuration, shared by `gobyd --check` ([`check`])
/// and the daemon's start ([`Builder::start`](crate::daemon::Builder::start),
/// with [`DriverSettings::Caller`](config::DriverSettings::Caller) when the
/// caller gives the drivers): what it refuses the daemon never runs with, and
/// what it accepts the daemon starts with unless something only starting
/// shows (a serial device that is not a terminal; what `--check` can see
/// would clash on this machine, a port taken or a data directory held by
/// another daemon, it tells beside: [`crate::clash`]).
///
/// In order: the configuration is completed; every setting that cannot
/// work is found at once ([`config::problems`]: each named by its field,
/// including a TDMA slot too short for a packet of its rate on the
/// driver); then the MQTT settings, the DCCL types, the translator, the
/// queues and the medium access settings, each refused with its own error.
pub fn validate(
    config: GobydConfig,
    driver: config::DriverSettings,
) -> Result<Checked, DaemonError> {
    let config = match config::complete(config.clone()) {
        Ok(completed) => completed,
        Err(ConfigError::Problems(mut problems)) => {
            // The link rules against the DCCL types, told beside (every
            // problem at once, not one stage at a time).
            if let Ok(defs) = config::load_definitions(&config) {
                problems.extend(config::links::rule_problems(&config, &defs.loaded));
            }
            return Err(ConfigError::Problems(problems).into());
        }
        Err(e) => return Err(e.into()),
    };
    let mut problems = config::problems(&config, driver);
    if let Some(forecast) = &config.forecast {
        if let Err(p) = crate::forecast::settings::Settings::load(
            forecast,
            crate::forecast::moos_origin(&config),
        ) {
            problems.extend(p);
        }
    }
    // Each MAC's own refusals, in the same list (every problem at once).
    let mut mac = Ok(());
    for view in config::links::links(&config) {
        let made = MacManager::new(view.mac.expect("completed"), SystemClock.now());
        if let Err(amac::AmacError::InvalidField { field, reason, .. }) = &made {
            let field = view.field(&format!("mac.{field}"));
            if !problems.iter().any(|p| p.field == field) {
                problems.push(config::Problem::new(field, reason.clone()));
            }
        }
        if let (Err(e), Ok(())) = (made, &mac) {
            mac = Err(e);
        }
    }
    if !problems.is_empty() {
        return Err(ConfigError::Problems(problems).into());
    }
    if let Some(mqtt) = &config.mqtt {
        crate::edge::mqtt::settings::settings(mqtt, config.modem_id())?;
    }
    let defs = config::load_definitions(&config)?;
    let mut codec = Arc::new(defs.codec);
    let mut queue = config.queue.clone().unwrap_or_default();
    let configured = queue.message_entry.len();
    config::default_entries(&mut queue, &defs.loaded);
    // Each queue entry on its own, so that every refused entry is told at
    // once, at its place.
    let mut problems = entry_problems(&codec, &queue, configured, &defs.loaded);
    problems.extend(config::links::rule_problems(&config, &defs.loaded));
    problems.extend(config::script::problems(&config, |name| {
        codec.max_size(name).ok()
    }));
    if problems.is_empty() {
        problems.extend(frame_problems(&codec, &queue, configured, &config));
    }
    if !problems.is_empty() {
        return Err(ConfigError::Problems(problems).into());
    }
    // The network layer's own types (routing, fragments), when it is on.
    crate::core::network::prepare(
        &config,
        Arc::get_mut(&mut codec).expect("the codec is not shared yet"),
        &mut queue,
        &defs.loaded,
    )
    .map_err(ConfigError::Problems)?;
    config::links::queue_links(&config, |n| codec.id_of(n).ok())
        .map_err(config::ConfigError::Invalid)?;
    crate::translator::from_config(&config, &codec).map_err(config::ConfigError::Invalid)?;
    QueueManager::new(codec.clone(), &queue)?;
    mac?;
    Ok(Checked {
        config,
        codec,
        loaded: defs.loaded,
        queue,
    })
}

/// The settings of `queue` the queue refuses (a problem of `queue`, and
/// then nothing else), or the queue entries it refuses: each of the first
/// `configured` (written in the configuration) as a problem of its
/// `queue.message_entry[i].protobuf_name` (with the DCCL types `loaded`
/// when the entry's type is not one of them), each of the others (a loaded
/// type given the default settings) as a problem of `dccl.proto_file`.
fn entry_problems(
    codec: &Arc<dccl::Codec>,
    queue: &protos::goby::acomms::protobuf::QueueManagerConfig,
    configured: usize,
    loaded: &[String],
) -> Vec<config::Problem> {
    // The settings of the queue itself (the ack wait, the hold of retries)
    // are its own problem, not one of each entry.
    let settings = protos::goby::acomms::protobuf::QueueManagerConfig {
        message_entry: Vec::new(),
        ..queue.clone()
    };
    if let Err(e) = QueueManager::new(codec.clone(), &settings) {
        let reason = match e {
            queue::QueueError::Config { reason, .. } => reason,
            other => other.to_string(),
        };
        // The queue's reasons begin with the setting they are about.
        let setting = reason.split(' ').next().unwrap_or_default();
        let field = if !setting.is_empty()
            && setting.bytes().all(|b| b.is_ascii_lowercase() || b == b'_')
        {
            format!("queue.{setting}")
        } else {
            "queue".to_string()
        };
        return vec![config::Problem::new(field, reason)];
    }
    let mut problems = Vec::new();
    for (i, entry) in queue.message_entry.iter().enumerate() {
        let alone = protos::goby::acomms::protobuf::QueueManagerConfig {
            message_entry: vec![entry.clone()],
            ..queue.clone()
        };
        let Err(e) = QueueManager::new(codec.clone(), &alone) else {
            continue;
        };
        let mut reason = match e {
            queue::QueueError::Config { reason, .. } => reason,
            other => other.to_string(),
        };
        if codec.descriptor(&entry.protobuf_name).is_none() {
            reason = format!(
                "{:?} is not a DCCL type of the loaded .proto files (loaded: {})",
                entry.protobuf_name,
                if loaded.is_empty() {
                    "none".to_string()
                } else {
                    loaded.join(", ")
                }
            );
        }
        problems.push(if i < configured {
            config::Problem::new(format!("queue.message_entry[{i}].protobuf_name"), reason)
        } else {
            config::Problem::new(
                "dccl.proto_file",
                format!(
                    "{} (loaded, queued with the default settings as it has no queue entry): {reason}",
                    entry.protobuf_name
                ),
            )
        });
    }
    problems
}

/// The queue entries whose messages can be larger than the largest frame
/// the driver sends ([`modemdriver::check::largest_frame`]: the EvoLogics
/// S2C's burst size): such a message would never go. With several links,
/// larger than the largest frame of every link the type may use
/// ([`config::links`]), with its identity trailer (such a type never goes
/// without it). None with the network layer on: it sends a message larger
/// than a frame to one node in fragments (and refuses a broadcast of one
/// when it is published, saying why).
fn frame_problems(
    codec: &Arc<dccl::Codec>,
    queue: &protos::goby::acomms::protobuf::QueueManagerConfig,
    configured: usize,
    config: &GobydConfig,
) -> Vec<config::Problem> {
    if config.network.is_some() {
        return Vec::new();
    }
    let views = config::links::links(config);
    let rules = config::links::queue_links(config, |n| codec.id_of(n).ok())
        .ok()
        .flatten();
    let mut problems = Vec::new();
    for (i, entry) in queue.message_entry.iter().enumerate() {
        let Ok(size) = codec.max_size(&entry.protobuf_name) else {
            continue;
        };
        let allowed: Vec<&config::links::LinkView<'_>> =
            match (&rules, codec.id_of(&entry.protobuf_name).ok()) {
                (Some(links), Some(id)) => links.order(id).iter().map(|&k| &views[k]).collect(),
                _ => views.iter().collect(),
            };
        // Each link's largest frame; a link without a limit of its own
        // carries any message the queue takes.
        let Some(limits) = allowed
            .iter()
            .map(|v| {
                let driver = v.driver?;
                Some((modemdriver::check::largest_frame(driver)?, *v, driver))
            })
            .collect::<Option<Vec<_>>>()
        else {
            continue;
        };
        // A type of several links carries its identity trailer in every
        // frame (the queue never sends it without: `queue::links`).
        let trailer = if allowed.len() > 1 && queue.message_identity.unwrap_or(true) {
            queue::identity::TrailerCodec::new().size(1)
        } else {
            0
        };
        if limits.is_empty()
            || limits
                .iter()
                .any(|(largest, _, _)| size + trailer <= *largest)
        {
            continue;
        }
        let with_trailer = if trailer > 0 {
            format!(" (with the identity trailer of {trailer} bytes a type of several links carries, {} bytes)", size + trailer)
        } else {
            String::new()
        };
        let field = if i < configured {
            format!("queue.message_entry[{i}].protobuf_name")
        } else {
            "dccl.proto_file".to_string()
        };
        let reason = match limits.as_slice() {
            [(largest, view, driver)] if view.section.is_none() => format!(
                "{} encodes to up to {size} bytes, more than the {largest} bytes of the driver's largest frame \
                 ({}): it could never be sent",
                entry.protobuf_name,
                modemdriver::check::limits(driver).unwrap_or_default()
            ),
            many => format!(
                "{} encodes to up to {size} bytes{with_trailer}, more than the largest frame of every link \
                 it may use ({}): it could never be sent",
                entry.protobuf_name,
                many.iter()
                    .map(|(largest, view, _)| format!("{}: {largest} bytes", view.name))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        };
        problems.push(config::Problem::new(field, reason));
    }
    problems
}

/// The frame limits of the configured drivers, in words, when they have
/// such limits (told by `gobyd --check`): one line, or with `link`
/// sections one per link that has them (`link NAME: ...`).
pub fn driver_limits(config: &GobydConfig) -> Option<String> {
    let lines: Vec<String> = config::links::links(config)
        .iter()
        .filter_map(|v| {
            let limits = modemdriver::check::limits(v.driver?)?;
            Some(match v.section {
                Some(_) => format!("link {}: {limits}", v.name),
                None => limits,
            })
        })
        .collect();
    (!lines.is_empty()).then(|| lines.join("\n"))
}

/// Below this `minimum_ack_wait_seconds`, `gobyd --check` warns that an
/// Iridium message is sent again before its ack can come.
pub const MIN_SBD_ACK_WAIT_SECONDS: f64 = 60.0;

/// What the DCCL types loaded define that cannot do what its writer meant
/// ([`dccl::Codec::load_warnings`]): a dynamic condition libdccl ignores,
/// a script naming no field of its message, a script reading a field a
/// receiver decodes after it. Each "Type.field: dynamic_conditions.KIND
/// \"SCRIPT\" why", in the order the types were loaded.
pub fn definition_warnings(checked: &Checked) -> Vec<String> {
    checked
        .loaded
        .iter()
        .flat_map(|name| checked.codec.load_warnings(name).unwrap_or_default())
        .map(|w| w.to_string())
        .collect()
}

/// What `gobyd --check` tells of a driver whose frames have a size limit
/// of their own (Iridium SBD): the limits, and a warning for each loaded
/// DCCL type that can be larger than the frames this node sends (it can
/// never be sent from here; a type only received is fine).
///
/// With `link` sections, for each link with such limits (its lines begin
/// `link NAME: `), each type warned about only when it may use that link.
///
/// The warnings also hold each type larger than every frame this node's
/// own TDMA slots offer ([`slot_frame_warnings`]), whatever the driver.
pub fn frame_report(checked: &Checked) -> (Option<String>, Vec<String>) {
    let config = &checked.config;
    let rules = config::links::queue_links(config, |n| checked.codec.id_of(n).ok())
        .ok()
        .flatten();
    let mut lines = Vec::new();
    let mut warnings = slot_frame_warnings(checked);
    warnings.extend(serve_dir_warning(config));
    let mut sbd = None;
    for view in config::links::links(config) {
        let Some(limits) = view.driver.and_then(modemdriver::check::frame_limits) else {
            continue;
        };
        let named = |text: String| match view.section {
            Some(_) => format!("link {}: {text}", view.name),
            None => text,
        };
        for name in &checked.loaded {
            let may_use = match (&rules, checked.codec.id_of(name).ok()) {
                (Some(links), Some(id)) => links.order(id).contains(&view.index),
                _ => true,
            };
            // With the network layer on, it goes to one node in fragments.
            if !may_use || config.network.is_some() {
                continue;
            }
            if let Ok(size) = checked.codec.max_size(name) {
                if size > limits.outgoing {
                    warnings.push(named(format!(
                        "{name} is up to {size} bytes, more than the {} bytes of the frames this node sends over {}: \
                         a message of it that large is never sent from here (only received)",
                        limits.outgoing, limits.link
                    )));
                }
            }
        }
        lines.push(named(format!("{}: {}", limits.link, limits.text)));
        sbd.get_or_insert(limits);
    }
    let Some(limits) = sbd else {
        return (None, warnings);
    };
    let wait = checked.queue.minimum_ack_wait_seconds();
    if wait < MIN_SBD_ACK_WAIT_SECONDS {
        warnings.push(format!(
            "queue.minimum_ack_wait_seconds is {wait}: over {} an acknowledgement takes a session each way \
             (and a ring alert or a mailbox check), so a message not yet acknowledged is sent again, \
             and paid for, at each of this node's slots; set it to the time an ack takes \
             (e.g. {MIN_SBD_ACK_WAIT_SECONDS})",
            limits.link
        ));
    }
    (Some(lines.join("\n")), warnings)
}

/// A warning when `network.serve_dir` is set but is not a directory here
/// (relative: to the directory `gobyd` runs in): every `file_get` of
/// another node is then refused, saying so, until it is.
fn serve_dir_warning(config: &GobydConfig) -> Option<String> {
    let dir = config.network.as_ref()?.serve_dir.as_deref()?;
    let path = std::path::Path::new(dir);
    let what = match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => return None,
        Ok(_) => "is not a directory",
        Err(_) => "does not exist",
    };
    Some(format!(
        "network.serve_dir: {dir:?} {what} (relative: to the directory gobyd runs in): \
         every file another node asks for is refused until it is a directory"
    ))
}

/// A warning for each loaded DCCL type that fits a frame of the driver
/// (else `--check` refuses it) but no frame this node's own slots of fixed
/// TDMA offer ([`modemdriver::check::frame_in_slot`]: a Micro-Modem's of
/// the slots' rates, an EvoLogics instant message in a slot of `dest: -1`)
/// on any link the type may use: a message of it that large waits until a
/// slot offers a larger frame (a `MACUpdate` to a higher rate, a slot
/// naming one node). None with the network layer on (it fragments such a
/// message), with a MAC switcher, or for a link whose slots are not fixed
/// TDMA or whose frames are not known.
pub fn slot_frame_warnings(checked: &Checked) -> Vec<String> {
    let config = &checked.config;
    if config.network.is_some() || config.mac_switcher.is_some() {
        return Vec::new();
    }
    let me = config.modem_id();
    let views = config::links::links(config);
    // Each link's largest frame in its own slots (`None`: not known).
    let in_slots: Vec<Option<usize>> = views
        .iter()
        .map(|view| {
            let fixed = view.mac?.r#type()
                == protos::goby::acomms::protobuf::MacType::MacFixedDecentralized;
            let frames = view.own_slot_frames(me);
            if !fixed || view.driver.is_none() || frames.is_empty() {
                return None;
            }
            frames
                .into_iter()
                .collect::<Option<Vec<usize>>>()?
                .into_iter()
                .max()
        })
        .collect();
    let rules = config::links::queue_links(config, |n| checked.codec.id_of(n).ok())
        .ok()
        .flatten();
    let mut warnings = Vec::new();
    for name in &checked.loaded {
        let Ok(size) = checked.codec.max_size(name) else {
            continue;
        };
        let allowed: Vec<usize> = match (&rules, checked.codec.id_of(name).ok()) {
            (Some(links), Some(id)) => links.order(id).to_vec(),
            _ => (0..views.len()).collect(),
        };
        // Every link it may use has known slot frames, all too small, and
        // a driver frame it fits (a type no frame holds is refused).
        let Some(frames) = allowed
            .iter()
            .map(|&k| in_slots.get(k).copied().flatten().map(|f| (k, f)))
            .collect::<Option<Vec<(usize, usize)>>>()
        else {
            continue;
        };
        let fits_a_driver = allowed.iter().any(|&k| {
            views[k]
                .driver
                .and_then(modemdriver::check::largest_frame)
                .is_none_or(|largest| size <= largest)
        });
        if frames.is_empty() || frames.iter().any(|&(_, f)| size <= f) || !fits_a_driver {
            continue;
        }
        let offered = frames
            .iter()
            .map(|&(k, f)| {
                let view = &views[k];
                match view.section {
                    Some(_) => format!("link {}: {f} bytes", view.name),
                    None => format!("{f} bytes"),
                }
            })
            .collect::<Vec<_>>()
            .join(", ");
        warnings.push(format!(
            "{name} encodes to up to {size} bytes, more than every frame this node's TDMA slots \
             offer (the largest, {offered}): a message of it that large waits until a slot offers \
             a larger frame (a higher rate, by MACUpdate; on an EvoLogics, a slot naming one node \
             for burst data), or goes in fragments with the network layer on"
        ));
    }
    warnings
}

/// Checks a configuration without starting anything ([`validate`], the
/// driver's settings included). Returns the DCCL types.
pub fn check(config: GobydConfig) -> Result<Vec<String>, DaemonError> {
    validate(config, config::DriverSettings::Configured).map(|checked| checked.loaded)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `network.serve_dir` set but not a directory is warned of: missing,
    /// or a file; a directory, or no `serve_dir`, is not.
    #[test]
    fn a_serve_dir_that_is_no_directory_is_warned_of() {
        let with = |dir: Option<&str>| GobydConfig {
            network: Some(protos::goby::apps::protobuf::NetworkConfig {
                serve_dir: dir.map(str::to_string),
                ..Default::default()
            }),
            ..Default::default()
        };
        let here = std::env::temp_dir();
        let missing = here.join(format!("goby-no-such-dir-{}", std::process::id()));
        let file = here.join(format!("goby-serve-file-{}", std::process::id()));
        std::fs::write(&file, b"x").unwrap();
        let missing_text = serve_dir_warning(&with(missing.to_str())).unwrap_or_default();
        assert!(missing_text.contains("does not exist"), "{missing_text}");
        let file_text = serve_dir_warning(&with(file.to_str())).unwrap_or_default();
        assert!(file_text.contains("is not a directory"), "{file_text}");
        assert_eq!(serve_dir_warning(&with(here.to_str())), None);
        assert_eq!(serve_dir_warning(&with(None)), None);
        assert_eq!(serve_dir_warning(&GobydConfig::default()), None);
        let _ = std::fs::remove_file(&file);
    }
    use crate::daemon::Daemon;

    /// A scratch directory of this test process.
    fn scratch(name: &str) -> std::path::PathBuf {
        let dir =
            std::env::temp_dir().join(format!("gobyd-validate-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// The error of `gobyd --check` on `text`, after checking that the
    /// daemon's start refuses it with the same one.
    async fn refused(text: &str) -> String {
        let config = config::parse(text, "test").expect("parses");
        let by_check = check(config.clone()).expect_err(text).to_string();
        let by_start = Daemon::builder(config)
            .start()
            .await
            .expect_err(text)
            .to_string();
        assert_eq!(by_check, by_start, "{text}");
        by_check
    }

    fn assert_names(err: &str, parts: &[&str]) {
        for part in parts {
            assert!(err.contains(part), "{part:?} missing from {err}");
        }
    }

    #[tokio::test]
    async fn a_scripted_slot_of_an_unknown_type_or_one_over_its_rates_frame_is_refused() {
        let dir = scratch("script");
        let err = refused(&format!(
            "modem_id: 1\ndata_dir: \"{}\"\njson {{ tcp_bind: \"\" }}\n\
             mac {{ type: MAC_FIXED_DECENTRALIZED \
             slot {{ src: 1 rate: 1 slot_seconds: 10 packet_type: \"goby.example.Comand\" }} \
             slot {{ src: 1 rate: 0 slot_seconds: 20 packet_type: \"goby.example.NavigationReport\" packet_type: \"any\" }} }}\n",
            dir.display()
        ))
        .await;
        assert_names(
            &err,
            &[
                "mac.slot[0].packet_type[0]",
                "\"goby.example.Comand\" is not a loaded DCCL type",
            ],
        );
        let ok = format!(
            "modem_id: 1\ndata_dir: \"{}\"\n\
             mac {{ type: MAC_FIXED_DECENTRALIZED \
             slot {{ src: 1 rate: 1 slot_seconds: 10 packet_type: \"goby.example.Command\" }} }}\n",
            dir.display()
        );
        check(config::parse(&ok, "test").unwrap()).expect("a scripted slot of a loaded type");
    }

    /// A type larger than every frame of the node's slots (but not than
    /// the driver's) is warned of, naming the frame; not once a slot's rate
    /// holds it, nor with the network layer on.
    #[test]
    fn a_type_over_every_frame_of_the_nodes_slots_is_warned_of() {
        let dir = scratch("slot-frames");
        let proto = dir.join("big.proto");
        std::fs::write(
            &proto,
            "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage test;\n\
             message Big {\n  option (dccl.msg) = { id: 120 max_bytes: 60 codec_version: 4 };\n  \
             required bytes data = 1 [(dccl.field).max_length = 50];\n}\n",
        )
        .unwrap();
        let warnings = |rate: u32, extra: &str| {
            let text = format!(
                "modem_id: 1\ndata_dir: \"{}\"\ndccl {{ proto_file: \"{}\" }}\n\
                 mac {{ type: MAC_FIXED_DECENTRALIZED slot {{ src: 1 rate: {rate} slot_seconds: 10 }} \
                 slot {{ src: 2 rate: 5 slot_seconds: 10 }} }}\n{extra}",
                dir.display(),
                proto.display()
            );
            let checked = validate(
                config::parse(&text, "test").unwrap(),
                config::DriverSettings::Configured,
            )
            .expect("valid");
            slot_frame_warnings(&checked)
        };
        let at_rate_0 = warnings(0, "");
        assert_eq!(at_rate_0.len(), 1, "{at_rate_0:?}");
        assert!(
            at_rate_0[0].starts_with("test.Big encodes to up to 52 bytes")
                && at_rate_0[0].contains("(the largest, 32 bytes)"),
            "{at_rate_0:?}"
        );
        // Node 2's rate-5 slot is not this node's.
        assert_eq!(warnings(2, ""), Vec::<String>::new());
        assert_eq!(warnings(0, "network { }\n"), Vec::<String>::new());
    }

    #[tokio::test]
    async fn a_micromodem_slot_too_short_for_its_rate_is_refused() {
        let pty = modemdriver::link::serial::open_pty_pair().unwrap();
        let text = format!(
            "modem_id: 1\ndriver {{ driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"{}\" }}\n\
             mac {{ type: MAC_FIXED_DECENTRALIZED slot {{ src: 1 rate: 2 slot_seconds: 1 }} slot {{ src: 2 rate: 2 slot_seconds: 5 }} }}\n",
            pty.path
        );
        let err = refused(&text).await;
        assert_names(
            &err,
            &["configuration: mac.slot[0].slot_seconds: 1 s is too short for a rate-2 packet of 3 frames \
               on the Micro-Modem (needs at least 4.2 s: 3 frames of 64 bytes at 500 bit/s take 3.07 s, \
               1 s of probe and header, 0.1 s for the driver to hand the data over)"],
        );
        // The other slot holds its packet: one problem only.
        assert!(!err.contains("slot[1]"), "{err}");
        // The MAC's guard time comes off the slot.
        let guarded = text.replace(
            "type: MAC_FIXED_DECENTRALIZED",
            "type: MAC_FIXED_DECENTRALIZED guard_seconds: 1",
        );
        let err = refused(&guarded).await;
        assert_names(
            &err,
            &[
                "mac.slot[1].slot_seconds: 5 s is too short",
                "guard_seconds 1",
                "needs at least 5.2 s",
            ],
        );
    }

    #[tokio::test]
    async fn a_simulator_slot_shorter_than_its_packet_is_refused() {
        let text = "modem_id: 1\nmac { type: MAC_FIXED_DECENTRALIZED slot { src: 1 rate: 6 slot_seconds: 1 } }\n";
        let err = refused(text).await;
        assert_names(
            &err,
            &["mac.slot[0].slot_seconds: 1 s is too short for a rate-6 packet of 6 frames on the simulator \
               (needs at least 1.2 s: 6 frames of 32 bytes at 2400 bit/s take 0.64 s, 0.5 s of probe and header)"],
        );
        // With a shorter packet overhead the same slot holds the packet,
        // and what --check accepts the daemon runs.
        let dir = scratch("sim-slot");
        let text = format!(
            "modem_id: 1\ndriver {{ driver_type: DRIVER_ACOUSTIC_SIMULATOR simulator {{ node {{ modem_id: 1 }} \
             packet_overhead_seconds: 0.05 channel: \"validate-sim-slot\" }} }}\n\
             mac {{ type: MAC_FIXED_DECENTRALIZED slot {{ src: 1 rate: 6 slot_seconds: 1 }} }}\n\
             json {{ tcp_bind: \"\" }}\ndata_dir: \"{}\"\n",
            dir.display()
        );
        let config = config::parse(&text, "test").unwrap();
        check(config.clone()).expect("valid");
        let daemon = Daemon::builder(config).start().await.expect("starts");
        daemon.run(async {}).await.unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[tokio::test]
    async fn adaptive_rate_is_refused_on_a_driver_without_the_micromodems_rates() {
        let udp = "modem_id: 1\ndriver { driver_type: DRIVER_UDP udp { local { port: 0 } \
                   remote { modem_id: 2 port: 50001 } } }\n\
                   mac { type: MAC_FIXED_DECENTRALIZED adaptive_rate: true \
                   slot { src: 1 dest: 2 rate: 1 slot_seconds: 10 } \
                   slot { src: 1 dest: 2 rate: 1 slot_seconds: 10 adaptive_rate: true } }\n";
        let err = refused(udp).await;
        assert_names(
            &err,
            &[
                "mac.adaptive_rate: true, but adaptive_rate chooses among the WHOI Micro-Modem's \
                 rates (0, 1, 3, 5) and the DRIVER_UDP driver does not have them",
                "mac.slot[1].adaptive_rate: true",
            ],
        );
        assert!(!err.contains("slot[0]"), "{err}");
        // The simulator models the Micro-Modem's rates: accepted there.
        let dir = scratch("sim-adaptive");
        let sim = format!(
            "modem_id: 1\ndriver {{ driver_type: DRIVER_ACOUSTIC_SIMULATOR simulator {{ node {{ modem_id: 1 }} \
             channel: \"validate-sim-adaptive\" }} }}\n\
             mac {{ type: MAC_FIXED_DECENTRALIZED adaptive_rate: true \
             slot {{ src: 1 dest: 2 rate: 1 slot_seconds: 10 adaptive_rate: true }} }}\n\
             json {{ tcp_bind: \"\" }}\ndata_dir: \"{}\"\n",
            dir.display()
        );
        let config = config::parse(&sim, "test").unwrap();
        check(config.clone()).expect("adaptive_rate on the simulator");
        let daemon = Daemon::builder(config).start().await.expect("starts");
        daemon.run(async {}).await.unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[tokio::test]
    async fn out_of_range_addresses_and_numbers_are_refused_naming_each_field() {
        let err = refused(
            "modem_id: 1\ndriver { driver_type: DRIVER_UDP udp { local { port: 70000 } \
             remote { modem_id: 2 ip: \"not-an-ip\" port: 50001 } remote { modem_id: 3 port: 0 } } }\n",
        )
        .await;
        assert_names(
            &err,
            &[
                "3 settings cannot work:",
                "driver.udp.local.port: 70000 is not a UDP port (0-65535)",
                "driver.udp.remote[0].ip: \"not-an-ip\" is not an IP address",
                "driver.udp.remote[1].port: 0 is not a port to send to",
            ],
        );
        let err = refused(
            "modem_id: 1\ndriver { driver_type: DRIVER_ACOUSTIC_SIMULATOR simulator { node { modem_id: 1 } \
             packet_loss: 1.5 sound_speed: 0 packet_overhead_seconds: -1 udp_local { port: 70000 } \
             udp_peer { ip: \"not-an-ip\" port: 50002 } } }\n\
             moos { port: 70000 }\nduplicate_window_seconds: -1\n",
        )
        .await;
        assert_names(
            &err,
            &[
                "moos.port: 70000 is not the MOOSDB's TCP port (1-65535)",
                "duplicate_window_seconds: -1 is not a time in seconds",
                "driver.simulator.sound_speed: 0 is not a speed",
                "driver.simulator.packet_loss: 1.5 is not a probability (0 to 1",
                "driver.simulator.packet_overhead_seconds: -1 is not a time in seconds",
                "driver.simulator.udp_local.port: 70000 is not a UDP port",
                "driver.simulator.udp_peer[0].ip: \"not-an-ip\" is not an IP address",
            ],
        );
    }

    #[tokio::test]
    async fn a_micromodem_serial_port_that_does_not_exist_is_refused() {
        let err = refused(
            "modem_id: 1\ndriver { driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/no-such-modem\" }\n",
        )
        .await;
        assert_names(
            &err,
            &["configuration: driver.serial_port: \"/dev/no-such-modem\" does not exist"],
        );
        let dir = scratch("serial-file");
        let file = dir.join("modem");
        std::fs::write(&file, "").unwrap();
        let err = refused(&format!(
            "modem_id: 1\ndriver {{ driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"{}\" }}\n",
            file.display()
        ))
        .await;
        assert_names(&err, &["driver.serial_port:", "is not a serial port"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[tokio::test]
    async fn the_trailer_id_is_refused_only_while_frames_carry_their_identity() {
        let dir = scratch("trailer-id");
        let proto = dir.join("clash.proto");
        std::fs::write(
            &proto,
            "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage test;\n\
             message Clash {\n  option (dccl.msg) = { id: 32001 max_bytes: 8 codec_version: 4 };\n\
             optional int32 x = 1 [(dccl.field) = { min: 0 max: 7 }];\n}\n",
        )
        .unwrap();
        let text = |queue: &str| {
            format!(
                "modem_id: 1\ndccl {{ load_examples: false proto_file: \"{}\" }}\n{queue}\n",
                proto.display()
            )
        };
        // gobyd turns message identity on unless told otherwise.
        for queue in ["", "queue { message_identity: true }"] {
            let err = refused(&text(queue)).await;
            assert_names(
                &err,
                &[
                    "test.Clash",
                    "DCCL id 32001 is reserved for the frame identity trailer",
                    "while message_identity is on",
                    "receivers read a message with this id as that trailer",
                    "set message_identity: false",
                ],
            );
        }
        let types =
            check(config::parse(&text("queue { message_identity: false }"), "test").unwrap())
                .expect("accepted without the trailer");
        assert_eq!(types, ["test.Clash"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[tokio::test]
    async fn a_start_on_a_callers_driver_leaves_the_driver_section_alone() {
        // The section names a serial port that does not exist and a slot
        // too short for the Micro-Modem: neither is the caller's driver's.
        let dir = scratch("caller");
        let text = format!(
            "modem_id: 1\ndriver {{ driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/no-such-modem\" }}\n\
             mac {{ type: MAC_FIXED_DECENTRALIZED slot {{ src: 1 rate: 2 slot_seconds: 1 }} }}\n\
             json {{ tcp_bind: \"\" }}\ndata_dir: \"{}\"\n",
            dir.display()
        );
        let config = config::parse(&text, "test").unwrap();
        assert!(check(config.clone()).is_err());
        let driver = modemdriver::sim::SimulatorDriver::start_on(
            &modemdriver::config::parse_text(
                "modem_id: 1 simulator { node { modem_id: 1 } } deferred_ack: true",
            )
            .unwrap(),
            modemdriver::sim::medium::Medium::named("validate-caller"),
        )
        .unwrap();
        let daemon = Daemon::builder(config)
            .driver(driver)
            .start()
            .await
            .expect("starts");
        daemon.run(async {}).await.unwrap();
        // The rest is checked all the same.
        let driver = modemdriver::sim::SimulatorDriver::start_on(
            &modemdriver::config::parse_text("modem_id: 1 simulator { node { modem_id: 1 } }")
                .unwrap(),
            modemdriver::sim::medium::Medium::named("validate-caller"),
        )
        .unwrap();
        let bad = config::parse(&format!("{text}log {{ level: \"loud\" }}\n"), "test").unwrap();
        let err = Daemon::builder(bad)
            .driver(driver)
            .start()
            .await
            .unwrap_err()
            .to_string();
        assert!(err.contains("log.level: \"loud\""), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
