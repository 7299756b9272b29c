//! A pAcommsHandler configuration (Goby 3 or Goby 2) read as gobyd's: every
//! key of pAcommsHandler's is mapped to gobyd's setting, noted as read and
//! not used, or refused with what to write instead, each with the place
//! where it is written.
//!
//! | pAcommsHandler key | gobyd |
//! |---|---|
//! | `modem_id`, `moos_var`, `translator_entry`, `modem_id_lookup_path` | the same fields |
//! | `driver_cfg`, `mac_cfg`, `queue_cfg` | `driver`, `mac`, `queue` (one name of each) |
//! | `[goby.acomms.udp.protobuf.config]`, `[goby.acomms.udp_multicast.protobuf.config]`, `[goby.acomms.micromodem.protobuf.config]`, `[goby.acomms.popoto.protobuf.config]`, `[goby.acomms.benthos.protobuf.config]` (Goby 3) | `udp`, `udp_multicast`, `micromodem`, `popoto`, `benthos` of the driver section |
//! | `[goby.acomms.micromodem.protobuf.transmission]` in a MAC slot (Goby 3) | the slot's `micromodem` (e.g. `type: MICROMODEM_FLEXIBLE_DATA` for an FDP slot) |
//! | `[UDPDriverConfig.local]`, `.remote`, `.max_frame_size` (Goby 2) | `udp.local`, `udp.remote`, `udp.max_frame_size` |
//! | `[micromodem.protobuf.Config.X]` (Goby 2) | `micromodem.X` (reset_nvram, nvram_cfg, keep_alive_seconds, allowed_skew_ms, use_application_acks, remus_lbl, narrowband_lbl) |
//! | `driver_type` (Goby 2, top level) | `driver.driver_type` (refused when the driver section names another driver) |
//! | `load_proto_file` | `dccl.proto_file`, after those of `dccl`, resolved as they are; the example messages are then not loaded (as pAcommsHandler loads only the files it is given) unless `dccl.load_examples` says so |
//! | `dccl_cfg.crypto_passphrase`, `.skip_crypto_for_id` | `dccl.passphrase`, `dccl.skip_crypto_for_id` |
//! | `dccl_cfg.id_codec` | accepted when DCCL's default (`dccl.default.id`), otherwise refused |
//! | `driver_failure_approach` with `CONTINUALLY_RESTART_DRIVER` | `driver_backoff_sec` (Goby's default 60) becomes `driver.reconnect_interval`; `new_driver_backoff_sec` noted as not used |
//! | `driver_failure_approach` with another technique | refused (it needs a listening driver) |
//! | `common.lat_origin`, `.lon_origin`, `.server_host`, `.server_port` | `moos.lat_origin`, `.lon_origin`, `.server`, `.port` (the MOOS interface is then on) |
//! | `common.verbosity` | `log.level`: QUIET off, WARN warn, VERBOSE info, DEBUG1 and DEBUG2 debug, DEBUG3 trace |
//! | `common.initializer` | `moos.initializer` (written to the MOOSDB on connecting) |
//! | `common.log`, `.log_path`, `.log_verbosity` | `log.dir` (`log_path`, or Goby's "./" for `log: true` alone; none with `log: false`), `log.file_level` (as `verbosity`): gobyd's log file, `gobyd.log` rotated by size |
//! | `common.log_omit_file_timestamp`, `.log_omit_latest_symlink` | noted as not used: the file is always `gobyd.log` |
//! | `common.app_tick`, `.comm_tick` | noted as not used: gobyd is driven by events, not by a tick |
//! | `common.community`, `.show_gui` | noted as not used |
//! | `common.time_warp_multiplier` | 1 accepted; another value refused (gobyd runs on the real clock) |
//! | `common.use_binary_protobuf`, `.moos_parser_technique` | accepted when they say what gobyd writes (`@PB[Name] text format`); otherwise refused |
//! | `route_cfg` | the `network` section's `route`, `subnet_mask` and `default_gateway` (routing through relays, the network layer on) |
//! | `load_shared_library` | refused: give the `.proto` files (`dccl { proto_file }`) |
//! | `listen_driver_cfg`, `listen_driver_type` | refused: gobyd runs one driver |
//! | `multiplex_create_moos_var`, `dccl_frontseat_forward_name` | refused: no equivalent |
//! | `transitional_cfg` (Goby 2) | refused: DCCL version 1 XML is not read |
//!
//! In a mission file's block, MOOS `KEY = value` lines are read too (see
//! `moos_lines`): the MOOS application settings ([`MOOS_APP_KEYS`]) are
//! noted as not used, a key naming a field of gobyd's configuration (any
//! case) sets it, any other key is refused.

use prost_reflect::{DynamicMessage, FieldDescriptor, Kind, ReflectMessage, Value};
use protos::goby::acomms::protobuf::{driver_config, DriverType};
use protos::goby::apps::protobuf::{
    goby_driver_failure_approach::DriverFailureTechnique,
    gobyd_config::moos_interface::Initializer, GobyVerbosity, GobydConfig,
};
use protos::goby::moos::protobuf::translator_entry::ParserSerializerTechnique;

use super::moos_lines::MoosLine;
use super::{Findings, NoteLevel, Places};

/// The settings of a polled MOOS application that a `ProcessConfig` block
/// may hold (read by MOOS's `CMOOSApp`); gobyd has no use for them.
pub const MOOS_APP_KEYS: &[&str] = &[
    "AppTick",
    "CommsTick",
    "MaxAppTick",
    "IterateMode",
    "SortMailByTime",
    "CatchCommandMessages",
];

/// Reads the MOOS lines of a block into `dynamic` (the block's protobuf
/// text, parsed); returns the fields they set with the offsets of their
/// keys.
pub(super) fn moos_lines(
    dynamic: &mut DynamicMessage,
    lines: &[MoosLine],
    found: &mut Findings<'_>,
) -> Vec<(String, usize)> {
    let desc = dynamic.descriptor();
    let mut assigned = Vec::new();
    let mut ignored: Vec<(&MoosLine, usize)> = Vec::new();
    for line in lines {
        if MOOS_APP_KEYS
            .iter()
            .any(|k| k.eq_ignore_ascii_case(&line.key))
        {
            let (number, _) = found.line_and_column(line.key_offset);
            ignored.push((line, number));
            continue;
        }
        let Some(field) = desc
            .fields()
            .find(|f| f.name().eq_ignore_ascii_case(&line.key))
        else {
            found.problem(
                Some(line.key_offset),
                &line.key,
                format!(
                    "{} = {} is neither a MOOS application setting ({}) nor a field of gobyd's configuration; \
                     write the setting in protobuf text format (field: value)",
                    line.key,
                    line.value,
                    MOOS_APP_KEYS.join(", ")
                ),
            );
            continue;
        };
        if matches!(field.kind(), Kind::Message(_)) {
            found.problem(
                Some(line.key_offset),
                field.name(),
                format!(
                    "{} is a section: write {} {{ ... }} (a KEY = value line sets one value)",
                    field.name(),
                    field.name()
                ),
            );
            continue;
        }
        let value = match moos_value(&field, &line.value) {
            Ok(value) => value,
            Err(reason) => {
                found.problem(Some(line.value_offset), field.name(), reason);
                continue;
            }
        };
        if field.is_list() {
            if let Some(list) = dynamic.get_field_mut(&field).as_list_mut() {
                list.push(value);
            }
        } else if dynamic.has_field(&field) || assigned.iter().any(|(n, _)| n == field.name()) {
            found.problem(
                Some(line.key_offset),
                field.name(),
                format!("{} is given twice (give it once)", field.name()),
            );
            continue;
        } else {
            dynamic.set_field(&field, value);
        }
        assigned.push((field.name().to_string(), line.key_offset));
    }
    if let Some((first, _)) = ignored.first() {
        let keys: Vec<String> = ignored
            .iter()
            .map(|(l, n)| format!("{} (line {n})", l.key))
            .collect();
        found.note(
            Some(first.key_offset),
            NoteLevel::Info,
            format!(
                "{}: MOOS application settings gobyd does not use (it is driven by events, not by a tick): ignored",
                keys.join(", ")
            ),
        );
    }
    assigned
}

/// The value of a MOOS line for `field` (a field that is not a section).
fn moos_value(field: &FieldDescriptor, raw: &str) -> Result<Value, String> {
    let name = field.name();
    let unquoted = raw
        .strip_prefix('"')
        .and_then(|r| r.strip_suffix('"'))
        .unwrap_or(raw);
    let number = |what: &str| format!("{name} = {raw}: {raw:?} is not {what}");
    Ok(match field.kind() {
        Kind::String => Value::String(unquoted.to_string()),
        Kind::Bytes => Value::Bytes(unquoted.as_bytes().to_vec().into()),
        Kind::Bool => match raw.to_ascii_lowercase().as_str() {
            "true" => Value::Bool(true),
            "false" => Value::Bool(false),
            other => Value::Bool(other.parse::<f64>().map_err(|_| number("true or false"))? > 0.0),
        },
        Kind::Int32 | Kind::Sint32 | Kind::Sfixed32 => {
            Value::I32(raw.parse().map_err(|_| number("a whole number"))?)
        }
        Kind::Int64 | Kind::Sint64 | Kind::Sfixed64 => {
            Value::I64(raw.parse().map_err(|_| number("a whole number"))?)
        }
        Kind::Uint32 | Kind::Fixed32 => Value::U32(
            raw.parse()
                .map_err(|_| number("a whole number, 0 or more"))?,
        ),
        Kind::Uint64 | Kind::Fixed64 => Value::U64(
            raw.parse()
                .map_err(|_| number("a whole number, 0 or more"))?,
        ),
        Kind::Float => Value::F32(raw.parse().map_err(|_| number("a number"))?),
        Kind::Double => Value::F64(raw.parse().map_err(|_| number("a number"))?),
        Kind::Enum(e) => {
            let value = e
                .get_value_by_name(raw)
                .or_else(|| e.get_value_by_name(&raw.to_ascii_uppercase()))
                .ok_or_else(|| {
                    format!(
                        "{name} = {raw}: not one of {}",
                        e.values()
                            .map(|v| v.name().to_string())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                })?;
            Value::EnumNumber(value.number())
        }
        Kind::Message(_) => return Err(format!("{name} is a section: write {name} {{ ... }}")),
    })
}

/// Goby 2's driver extensions and the fields of gobyd's driver section that
/// hold the same settings: (extension, section, field).
pub(super) const GOBY2_EXTENSIONS: &[(&str, &str, &str)] = &[
    ("UDPDriverConfig.local", "udp", "local"),
    ("UDPDriverConfig.remote", "udp", "remote"),
    ("UDPDriverConfig.max_frame_size", "udp", "max_frame_size"),
    (
        "micromodem.protobuf.Config.reset_nvram",
        "micromodem",
        "reset_nvram",
    ),
    (
        "micromodem.protobuf.Config.nvram_cfg",
        "micromodem",
        "nvram_cfg",
    ),
    (
        "micromodem.protobuf.Config.narrowband_lbl",
        "micromodem",
        "narrowband_lbl",
    ),
    (
        "micromodem.protobuf.Config.remus_lbl",
        "micromodem",
        "remus_lbl",
    ),
    (
        "micromodem.protobuf.Config.keep_alive_seconds",
        "micromodem",
        "keep_alive_seconds",
    ),
    (
        "micromodem.protobuf.Config.allowed_skew_ms",
        "micromodem",
        "allowed_skew_ms",
    ),
    (
        "micromodem.protobuf.Config.use_application_acks",
        "micromodem",
        "use_application_acks",
    ),
];

/// Moves the Goby 2 extensions written in the driver section (`driver` or
/// `driver_cfg`) of `dynamic` into the driver's `udp` and `micromodem`.
pub(super) fn goby2_extensions(
    dynamic: &mut DynamicMessage,
    places: &Places,
    found: &mut Findings<'_>,
) {
    for section in ["driver", "driver_cfg"] {
        if !dynamic.has_field_by_name(section) {
            continue;
        }
        let Some(driver) = dynamic
            .get_field_by_name_mut(section)
            .and_then(Value::as_message_mut)
        else {
            continue;
        };
        let written: Vec<(prost_reflect::ExtensionDescriptor, Value)> = driver
            .extensions()
            .map(|(ext, value)| (ext, value.clone()))
            .collect();
        for (ext, value) in written {
            driver.clear_extension(&ext);
            let path = format!("{section}.[{}]", ext.full_name());
            let Some((_, part, name)) = GOBY2_EXTENSIONS
                .iter()
                .find(|(full, _, _)| *full == ext.full_name())
            else {
                found.problem(
                    places.offset(&path),
                    &path,
                    "not a setting of a driver gobyd runs",
                );
                continue;
            };
            let Some(target) = driver
                .get_field_by_name_mut(part)
                .and_then(Value::as_message_mut)
            else {
                continue;
            };
            let Some(field) = target.descriptor().get_field_by_name(name) else {
                continue;
            };
            if target.has_field(&field) && !(field.is_list() && value.as_list().is_none()) {
                found.problem(
                    places.offset(&path),
                    &path,
                    format!(
                        "the same setting as {section}.{part}.{name}, which is given too (give one)"
                    ),
                );
                continue;
            }
            match (target.get_field_mut(&field).as_list_mut(), value) {
                (Some(list), Value::List(values)) => list.extend(values),
                (Some(list), one) => list.push(one),
                (None, one) => target.set_field(&field, one),
            }
        }
    }
}

/// Maps, notes or refuses every pAcommsHandler key of `config` (see the
/// table above), leaving none of them set.
pub(super) fn goby_keys(config: &mut GobydConfig, places: &Places, found: &mut Findings<'_>) {
    let refuse = |found: &mut Findings<'_>, path: String, reason: String| {
        found.problem(places.offset(&path), &path, reason);
    };
    for (path, what) in [
        (
            "load_shared_library",
            std::mem::take(&mut config.load_shared_library),
        ),
        (
            "multiplex_create_moos_var",
            std::mem::take(&mut config.multiplex_create_moos_var),
        ),
        (
            "dccl_frontseat_forward_name",
            std::mem::take(&mut config.dccl_frontseat_forward_name),
        ),
    ] {
        for (i, value) in what.iter().enumerate() {
            let reason = match path {
                "load_shared_library" => format!(
                    "gobyd loads no C++ libraries: give the .proto files {value:?} was generated from, \
                     as dccl {{ proto_file: \"PATH\" }} or load_proto_file: \"PATH\" (one a file)"
                ),
                "multiplex_create_moos_var" => format!(
                    "gobyd has no multiplexed create variable ({value:?}, as goby_liaison writes): \
                     remove it, and write each message to the create variables of its translator_entry"
                ),
                _ => format!(
                    "gobyd forwards no DCCL messages to iFrontSeat ({value}): remove it"
                ),
            };
            refuse(found, format!("{path}[{i}]"), reason);
        }
    }
    let files = std::mem::take(&mut config.load_proto_file);
    if !files.is_empty() {
        let dccl = config.dccl.get_or_insert_with(Default::default);
        // pAcommsHandler loads only the files it is given.
        dccl.load_examples.get_or_insert(false);
        for file in files {
            if !dccl.proto_file.contains(&file) {
                dccl.proto_file.push(file);
            }
        }
    }
    if let Some(t) = config.driver_type.take() {
        let driver = config.driver.get_or_insert_with(Default::default);
        let name = |t: i32| {
            DriverType::try_from(t)
                .map(|t| t.as_str_name().to_string())
                .unwrap_or_else(|_| t.to_string())
        };
        match &driver.driver {
            None => driver.driver = Some(driver_config::Driver::DriverType(t)),
            Some(driver_config::Driver::DriverType(same)) if *same == t => {}
            Some(driver_config::Driver::DriverType(other)) => refuse(
                found,
                "driver_type".into(),
                format!(
                    "{} differs from the driver section's driver_type {}: give the driver type once",
                    name(t),
                    name(*other)
                ),
            ),
            Some(driver_config::Driver::DriverName(n)) => refuse(
                found,
                "driver_type".into(),
                format!(
                    "the driver section names driver {n:?}: give driver_type or driver_name, not both"
                ),
            ),
        }
    }
    for i in 0..config.listen_driver_cfg.len() {
        refuse(
            found,
            format!("listen_driver_cfg[{i}]"),
            "gobyd runs one driver (driver_cfg); a listening driver has no equivalent: remove it \
             (a second modem needs a gobyd of its own; with mac { type: MAC_NONE } it only listens)"
                .into(),
        );
    }
    for i in 0..config.listen_driver_type.len() {
        refuse(
            found,
            format!("listen_driver_type[{i}]"),
            "gobyd runs one driver (driver_type); a listening driver has no equivalent: remove it"
                .into(),
        );
    }
    config.listen_driver_cfg.clear();
    config.listen_driver_type.clear();
    if let Some(approach) = config.driver_failure_approach.take() {
        driver_failure_approach(config, &approach, places, found);
    }
    if let Some(dccl_cfg) = config.dccl_cfg.take() {
        let dccl = config.dccl.get_or_insert_with(Default::default);
        if let Some(passphrase) = dccl_cfg.crypto_passphrase {
            if dccl.passphrase.is_some() || dccl.passphrase_file.is_some() {
                refuse(
                    found,
                    "dccl_cfg.crypto_passphrase".into(),
                    "the same setting as dccl.passphrase (or dccl.passphrase_file), which is given too: give one".into(),
                );
            } else {
                dccl.passphrase = Some(passphrase);
            }
        }
        for id in dccl_cfg.skip_crypto_for_id {
            if !dccl.skip_crypto_for_id.contains(&id) {
                dccl.skip_crypto_for_id.push(id);
            }
        }
        if let Some(codec) = dccl_cfg.id_codec {
            if codec != DEFAULT_ID_CODEC {
                refuse(
                    found,
                    "dccl_cfg.id_codec".into(),
                    format!(
                        "gobyd codes DCCL ids with DCCL's default identifier codec ({DEFAULT_ID_CODEC}); \
                         {codec:?} has no equivalent: remove id_codec (every node must then use the default)"
                    ),
                );
            }
        }
    }
    if let Some(route) = config.route_cfg.take() {
        route_cfg(config, route, places, found);
    }
    if config.transitional_cfg.take().is_some() {
        refuse(
            found,
            "transitional_cfg".into(),
            "gobyd does not read DCCL version 1 XML messages: remove transitional_cfg and give the messages as .proto files \
             (dccl { proto_file: \"PATH\" }; Goby 2 wrote them to its generated_proto_dir)"
                .into(),
        );
    }
    if let Some(common) = config.common.take() {
        self::common(config, common, places, found);
    }
}

/// Goby3's `route_cfg` (`goby.acomms.protobuf.RouteManagerConfig`): its
/// route, subnet mask and default gateway become the `network` section's
/// (the network layer is then on). A setting given in both is refused.
fn route_cfg(
    config: &mut GobydConfig,
    route: protos::goby::apps::protobuf::GobyRouteConfig,
    places: &Places,
    found: &mut Findings<'_>,
) {
    if route.route.as_ref().is_none_or(|r| r.hop.is_empty()) {
        // pAcommsHandler routes only with hops on its route.
        let text = if route.subnet_mask.is_some() || route.default_gateway.is_some() {
            "route_cfg has no hops: ignored, as pAcommsHandler does (it routes only along a route)"
        } else {
            "route_cfg is empty: ignored"
        };
        found.note(places.offset("route_cfg"), NoteLevel::Info, text.into());
        return;
    }
    let network = config.network.get_or_insert_with(Default::default);
    let mut both = Vec::new();
    if let Some(r) = route.route {
        if network.route.is_some() {
            both.push("route");
        } else {
            network.route =
                Some(protos::goby::apps::protobuf::network_config::StaticRoute { hop: r.hop });
        }
    }
    if let Some(mask) = route.subnet_mask {
        if network.subnet_mask.is_some() {
            both.push("subnet_mask");
        } else {
            network.subnet_mask = Some(mask);
        }
    }
    if let Some(gateway) = route.default_gateway {
        if network.default_gateway.is_some() {
            both.push("default_gateway");
        } else {
            network.default_gateway = Some(gateway);
        }
    }
    for field in both {
        let path = format!("route_cfg.{field}");
        found.problem(
            places.offset(&path),
            &path,
            format!("the same setting as network.{field}, which is given too: give one"),
        );
    }
    found.note(
        places.offset("route_cfg"),
        NoteLevel::Info,
        "route_cfg read as the network section (routing through relays, docs/routing.md)".into(),
    );
}

/// The identifier codec DCCL uses unless told otherwise.
const DEFAULT_ID_CODEC: &str = "dccl.default.id";

/// `driver_failure_approach`: restarting the failed driver is the driver's
/// reconnection.
fn driver_failure_approach(
    config: &mut GobydConfig,
    approach: &protos::goby::apps::protobuf::GobyDriverFailureApproach,
    places: &Places,
    found: &mut Findings<'_>,
) {
    let at = |path: &str| places.offset(path);
    if approach.technique() != DriverFailureTechnique::ContinuallyRestartDriver {
        found.problem(
            at("driver_failure_approach.technique"),
            "driver_failure_approach.technique",
            format!(
                "{} needs a listening driver (listen_driver_cfg), which gobyd does not have: \
                 use CONTINUALLY_RESTART_DRIVER or leave driver_failure_approach out \
                 (gobyd's Micro-Modem driver reopens the modem every driver_cfg.reconnect_interval seconds)",
                approach.technique().as_str_name()
            ),
        );
        return;
    }
    if approach.new_driver_backoff_sec.is_some() {
        found.note(
            at("driver_failure_approach.new_driver_backoff_sec"),
            NoteLevel::Warn,
            "driver_failure_approach.new_driver_backoff_sec is ignored: it applies when a listening driver takes over, and gobyd has none".into(),
        );
    }
    let backoff = approach.driver_backoff_sec();
    let path = "driver_failure_approach.driver_backoff_sec";
    let Ok(seconds) = u32::try_from(backoff) else {
        found.problem(
            at(path),
            path,
            format!("{backoff} is not a number of seconds (0 or more)"),
        );
        return;
    };
    let Some(driver) = config.driver.as_mut() else {
        found.note(
            at("driver_failure_approach"),
            NoteLevel::Info,
            "driver_failure_approach is ignored: there is no driver_cfg (gobyd runs its simulator)"
                .into(),
        );
        return;
    };
    let overridden = driver
        .micromodem
        .as_ref()
        .and_then(|m| m.reconnect_interval_ms)
        .is_some();
    match driver.reconnect_interval {
        Some(given) if given != seconds || overridden => found.problem(
            at(path),
            path,
            format!(
                "the same setting as driver_cfg.reconnect_interval ({given} s), which is given too: give one"
            ),
        ),
        _ if overridden => found.problem(
            at(path),
            path,
            "the same setting as driver_cfg's micromodem.reconnect_interval_ms, which is given too: give one",
        ),
        _ => driver.reconnect_interval = Some(seconds),
    }
}

/// `common { server_host server_port lat_origin lon_origin initializer }`:
/// the MOOS interface's settings (`moos`; the interface is then on), each
/// refused where `moos` gives another value too.
fn common_moos(
    config: &mut GobydConfig,
    common: protos::goby::apps::protobuf::GobyMoosAppConfig,
    at: &dyn Fn(&str) -> Option<usize>,
    found: &mut Findings<'_>,
) {
    let moos_settings = common.server_host.is_some()
        || common.server_port.is_some()
        || common.lat_origin.is_some()
        || common.lon_origin.is_some()
        || !common.initializer.is_empty();
    if !moos_settings {
        return;
    }
    let moos = config.moos.get_or_insert_with(Default::default);
    let both = |found: &mut Findings<'_>, goby: &str, ours: &str| {
        found.problem(
            at(goby),
            &format!("common.{goby}"),
            format!("the same setting as moos.{ours}, which is given too: give one"),
        );
    };
    if let Some(host) = common.server_host {
        match &moos.server {
            Some(given) if *given != host => both(found, "server_host", "server"),
            _ => moos.server = Some(host),
        }
    }
    if let Some(port) = common.server_port {
        match u32::try_from(port) {
            Err(_) => found.problem(
                at("server_port"),
                "common.server_port",
                format!("{port} is not the MOOSDB's TCP port (1-65535)"),
            ),
            Ok(port) => match moos.port {
                Some(given) if given != port => both(found, "server_port", "port"),
                _ => moos.port = Some(port),
            },
        }
    }
    for (goby, ours, value, slot) in [
        (
            "lat_origin",
            "lat_origin",
            common.lat_origin,
            &mut moos.lat_origin,
        ),
        (
            "lon_origin",
            "lon_origin",
            common.lon_origin,
            &mut moos.lon_origin,
        ),
    ] {
        if let Some(value) = value {
            match slot {
                Some(given) if *given != value => both(found, goby, ours),
                _ => *slot = Some(value),
            }
        }
    }
    for ini in common.initializer {
        moos.initializer.push(Initializer {
            // The same numbers: INI_DOUBLE 1, INI_STRING 2.
            r#type: ini.r#type,
            moos_var: ini.moos_var,
            global_cfg_var: ini.global_cfg_var,
            dval: ini.dval,
            sval: ini.sval,
            trim: ini.trim,
        });
    }
}

/// The log level of a Goby verbosity.
fn level_of(verbosity: i32) -> &'static str {
    match GobyVerbosity::try_from(verbosity) {
        Ok(GobyVerbosity::Quiet) => "off",
        Ok(GobyVerbosity::Warn) => "warn",
        Ok(GobyVerbosity::Debug1 | GobyVerbosity::Debug2) => "debug",
        Ok(GobyVerbosity::Debug3) => "trace",
        _ => "info",
    }
}

/// `common { log log_path log_verbosity }`: Goby's text log of a MOOS
/// application, as gobyd's log file (`log.dir`, `log.file_level`). Goby
/// writes it unless `log: false`; here it is written when `log: true` or a
/// `log_path` is given (Goby's default path "./" for `log: true` alone).
fn log_file(
    config: &mut GobydConfig,
    common: &protos::goby::apps::protobuf::GobyMoosAppConfig,
    at: &dyn Fn(&str) -> Option<usize>,
    found: &mut Findings<'_>,
) {
    let dir = match (common.log, &common.log_path) {
        (Some(false), _) | (None, None) => return,
        (_, Some(path)) => path.clone(),
        (Some(true), None) => "./".to_string(),
    };
    let log = config.log.get_or_insert_with(Default::default);
    let written = if common.log_path.is_some() {
        "log_path"
    } else {
        "log"
    };
    match &log.dir {
        Some(given) if *given != dir => found.problem(
            at(written),
            &format!("common.{written}"),
            "the same setting as log.dir, which is given too: give one",
        ),
        _ => log.dir = Some(dir),
    }
    if let Some(verbosity) = common.log_verbosity {
        match &log.file_level {
            Some(_) => found.problem(
                at("log_verbosity"),
                "common.log_verbosity",
                "the same setting as log.file_level, which is given too: give one",
            ),
            None => log.file_level = Some(level_of(verbosity).into()),
        }
    }
}

/// `common`: Goby's settings of every MOOS application.
fn common(
    config: &mut GobydConfig,
    common: protos::goby::apps::protobuf::GobyMoosAppConfig,
    places: &Places,
    found: &mut Findings<'_>,
) {
    let at = |field: &str| places.offset(&format!("common.{field}"));
    let mut ignored: Vec<String> = Vec::new();
    let mut ignore = |written: &[(&str, bool)], why: &str| {
        let names: Vec<&str> = written
            .iter()
            .filter(|(_, w)| *w)
            .map(|(n, _)| *n)
            .collect();
        if !names.is_empty() {
            ignored.push(format!("{} ({why})", names.join(", ")));
        }
    };
    ignore(
        &[
            (
                "log_omit_file_timestamp",
                common.log_omit_file_timestamp.is_some(),
            ),
            (
                "log_omit_latest_symlink",
                common.log_omit_latest_symlink.is_some(),
            ),
        ],
        "gobyd writes its log file as gobyd.log in log_path, rotated by size",
    );
    log_file(config, &common, &at, found);
    ignore(
        &[
            ("app_tick", common.app_tick.is_some()),
            ("comm_tick", common.comm_tick.is_some()),
        ],
        "gobyd is driven by events, not by a tick",
    );
    ignore(
        &[("community", common.community.is_some())],
        "gobyd does not use the vehicle's name",
    );
    ignore(
        &[("show_gui", common.show_gui.is_some())],
        "gobyd has no terminal display",
    );
    if !ignored.is_empty() {
        found.note(
            places.offset("common"),
            NoteLevel::Warn,
            format!("common: ignored: {}", ignored.join("; ")),
        );
    }
    if let Some(warp) = common.time_warp_multiplier {
        if warp != 1 {
            found.problem(
                at("time_warp_multiplier"),
                "common.time_warp_multiplier",
                format!(
                    "{warp}: gobyd runs on the real clock (its slots and timeouts are real seconds): remove it or make it 1"
                ),
            );
        }
    }
    if common.use_binary_protobuf == Some(true) {
        found.problem(
            at("use_binary_protobuf"),
            "common.use_binary_protobuf",
            "gobyd writes protobuf messages to MOOS variables as \"@PB[Name] text format\" only: remove it",
        );
    }
    if let Some(technique) = common.moos_parser_technique {
        let prefixed = ParserSerializerTechnique::TechniquePrefixedProtobufTextFormat;
        if technique != prefixed as i32 {
            found.problem(
                at("moos_parser_technique"),
                "common.moos_parser_technique",
                format!(
                    "{}: gobyd writes protobuf messages to MOOS variables as \"@PB[Name] text format\" ({}) only: remove it",
                    ParserSerializerTechnique::try_from(technique)
                        .map(|t| t.as_str_name())
                        .unwrap_or("this technique"),
                    prefixed.as_str_name()
                ),
            );
        }
    }
    if let Some(verbosity) = common.verbosity {
        let level = level_of(verbosity);
        let log = config.log.get_or_insert_with(Default::default);
        if log.level.is_some() {
            found.problem(
                at("verbosity"),
                "common.verbosity",
                "the same setting as log.level, which is given too: give one",
            );
        } else {
            log.level = Some(level.into());
        }
    }
    common_moos(config, common, &at, found);
}

#[cfg(test)]
mod tests {
    use super::super::{read, ConfigError, Layout, NoteLevel};
    use protos::goby::acomms::protobuf::{driver_config, DriverType};

    /// The problems of a text that is refused, as `place: field`.
    fn refusals(text: &str, layout: Layout) -> Vec<String> {
        match read(text, "b.moos", layout) {
            Err(ConfigError::Problems(problems)) => problems
                .iter()
                .map(|p| format!("{}: {}", p.place.as_deref().unwrap_or("?"), p.field))
                .collect(),
            other => panic!("{text}: {other:?}"),
        }
    }

    #[test]
    fn mappable_pacommshandler_keys_become_gobyds_settings() {
        let text = r#"common {
  log: true
  log_path: "/tmp"
  app_tick: 4
  comm_tick: 4
  verbosity: DEBUG1
  lat_origin: 42.5
  lon_origin: -70.5
  server_host: "10.0.0.2"
  server_port: 9001
  time_warp_multiplier: 1
  moos_parser_technique: TECHNIQUE_PREFIXED_PROTOBUF_TEXT_FORMAT
  initializer { type: INI_STRING moos_var: "VEHICLE" sval: " unicorn " }
}
modem_id: 2
load_proto_file: "a.proto"
load_proto_file: ["b.proto", "a.proto"]
dccl { proto_file: "c.proto" }
dccl_cfg { crypto_passphrase: "sesame" skip_crypto_for_id: 3 id_codec: "dccl.default.id" }
driver_failure_approach { technique: CONTINUALLY_RESTART_DRIVER driver_backoff_sec: 20 }
driver_cfg { driver_type: DRIVER_UDP [goby.acomms.udp.protobuf.config] { local { port: 1 } } }
route_cfg { }
"#;
        let read = read(text, "b.cfg", Layout::File).unwrap();
        let config = &read.config;
        let dccl = config.dccl.as_ref().unwrap();
        assert_eq!(dccl.proto_file, ["c.proto", "a.proto", "b.proto"]);
        assert_eq!(dccl.load_examples, Some(false));
        assert_eq!(dccl.passphrase(), "sesame");
        assert_eq!(dccl.skip_crypto_for_id, [3]);
        let moos = config.moos.as_ref().unwrap();
        assert_eq!((moos.server(), moos.port()), ("10.0.0.2", 9001));
        assert_eq!(
            (moos.lat_origin, moos.lon_origin),
            (Some(42.5), Some(-70.5))
        );
        assert_eq!(moos.initializer[0].sval(), " unicorn ");
        assert_eq!(config.log.as_ref().unwrap().level(), "debug");
        assert_eq!(config.log.as_ref().unwrap().dir.as_deref(), Some("/tmp"));
        assert_eq!(config.driver.as_ref().unwrap().reconnect_interval, Some(20));
        // None of Goby's keys is left.
        assert!(config.common.is_none() && config.dccl_cfg.is_none());
        assert!(config.load_proto_file.is_empty() && config.route_cfg.is_none());
        assert!(config.driver_failure_approach.is_none());
        // One warning names the common settings ignored, at `common`; the
        // empty route_cfg is noted.
        assert_eq!(read.notes.len(), 2, "{:?}", read.notes);
        let common = &read.notes[0];
        assert_eq!(common.level, NoteLevel::Warn);
        assert_eq!(common.place.as_deref(), Some("b.cfg:1:1"));
        assert!(
            common
                .text
                .contains("app_tick, comm_tick (gobyd is driven by events")
                && !common.text.contains("log_path")
                && common
                    .text
                    .contains("app_tick, comm_tick (gobyd is driven by events"),
            "{}",
            common.text
        );
        assert!(read.notes[1].text.contains("route_cfg is empty"));
    }

    #[test]
    fn gobys_text_log_becomes_the_log_file() {
        for (common, dir, level) in [
            ("log: true", Some("./"), None),
            ("log: false log_path: \"/x\"", None, None),
            (
                "log_path: \"/x\" log_verbosity: DEBUG3",
                Some("/x"),
                Some("trace"),
            ),
        ] {
            let text = format!("common {{ {common} }}\n");
            let config = read(&text, "b.cfg", Layout::File).unwrap().config;
            let log = config.log.unwrap_or_default();
            assert_eq!(log.dir.as_deref(), dir, "{common}");
            assert_eq!(log.file_level.as_deref(), level, "{common}");
        }
        let both = "log { dir: \"/y\" }\ncommon { log_path: \"/x\" }\n";
        assert_eq!(
            refusals(both, Layout::File),
            ["b.moos:2:10: common.log_path"]
        );
    }

    #[test]
    fn goby3_route_cfg_becomes_the_network_section() {
        let text = "modem_id: 2\nroute_cfg { route { hop: 1 hop: 2 hop: 3 } subnet_mask: 4294967040 default_gateway: 3 }\n";
        let read = read(text, "b.cfg", Layout::File).unwrap();
        let network = read.config.network.as_ref().unwrap();
        assert_eq!(network.route.as_ref().unwrap().hop, [1, 2, 3]);
        assert_eq!(network.subnet_mask(), 0xFFFF_FF00);
        assert_eq!(network.default_gateway, Some(3));
        assert!(read.config.route_cfg.is_none());
        // Given twice: refused.
        let both =
            "modem_id: 2\nnetwork { route { hop: 1 } }\nroute_cfg { route { hop: 1 hop: 2 } }\n";
        assert_eq!(
            refusals(both, Layout::File),
            ["b.moos:3:13: route_cfg.route"]
        );
    }

    #[test]
    fn keys_gobyd_cannot_map_are_refused_each_at_its_place() {
        let text = r#"modem_id: 1
load_shared_library: "libnav.so"
listen_driver_cfg { driver_type: DRIVER_UDP }
route_cfg { subnet_mask: 0xFFFF0000 }
common { time_warp_multiplier: 10 use_binary_protobuf: true }
multiplex_create_moos_var: "LIAISON_COMMANDER_OUT"
dccl_frontseat_forward_name: "goby.moos.protobuf.FrontSeatRaw"
dccl_cfg { id_codec: "my.id" }
driver_failure_approach { technique: MOVE_LISTEN_DRIVER_TO_PRIMARY }
transitional_cfg { message_file { path: "chat.xml" } }
listen_driver_type: DRIVER_UDP
"#;
        assert_eq!(
            refusals(text, Layout::File),
            [
                "b.moos:2:1: load_shared_library[0]",
                "b.moos:3:1: listen_driver_cfg[0]",
                "b.moos:5:10: common.time_warp_multiplier",
                "b.moos:5:35: common.use_binary_protobuf",
                "b.moos:6:1: multiplex_create_moos_var[0]",
                "b.moos:7:1: dccl_frontseat_forward_name[0]",
                "b.moos:8:12: dccl_cfg.id_codec",
                "b.moos:9:27: driver_failure_approach.technique",
                "b.moos:10:1: transitional_cfg",
                "b.moos:11:1: listen_driver_type[0]",
            ]
        );
        let e = read("load_shared_library: \"libnav.so\"", "b.cfg", Layout::File)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("b.cfg:1:1: load_shared_library[0]: gobyd loads no C++ libraries")
                && e.contains("\"libnav.so\"")
                && e.contains("dccl { proto_file: \"PATH\" }"),
            "{e}"
        );
        // A Goby key and gobyd's own setting of the same thing, differing.
        assert_eq!(
            refusals(
                "log { level: \"warn\" }\ncommon {\n  verbosity: QUIET\n  lat_origin: 1\n}\nmoos { lat_origin: 2 }\n",
                Layout::File
            ),
            ["b.moos:3:3: common.verbosity", "b.moos:4:3: common.lat_origin"]
        );
    }

    #[test]
    fn goby2_driver_type_and_extensions_become_the_driver_section() {
        let text = r#"modem_id: 1
driver_type: DRIVER_UDP
driver_cfg {
  [UDPDriverConfig.local] { port: 50001 }
  [UDPDriverConfig.remote] { ip: "127.0.0.1" port: 50002 }
  [UDPDriverConfig.max_frame_size]: 256
}
"#;
        let config = read(text, "b.cfg", Layout::File).unwrap().config;
        let driver = config.driver.unwrap();
        assert_eq!(
            driver.driver,
            Some(driver_config::Driver::DriverType(
                DriverType::DriverUdp as i32
            ))
        );
        let udp = driver.udp.unwrap();
        assert_eq!(udp.local.port, 50001);
        assert_eq!(udp.remote.len(), 1);
        assert_eq!(udp.remote[0].port, 50002);
        assert_eq!(udp.max_frame_size, Some(256));
        let mm = read(
            "driver_type: DRIVER_WHOI_MICROMODEM\ndriver_cfg {\n  serial_port: \"/dev/ttyUSB0\"\n  [micromodem.protobuf.Config.reset_nvram]: true\n  [micromodem.protobuf.Config.nvram_cfg]: \"DQF,1\"\n  [micromodem.protobuf.Config.nvram_cfg]: \"SNV,1\"\n}\n",
            "b.cfg",
            Layout::File,
        )
        .unwrap()
        .config;
        let mm = mm.driver.unwrap().micromodem.unwrap();
        assert_eq!(mm.reset_nvram, Some(true));
        assert_eq!(mm.nvram_cfg, ["DQF,1", "SNV,1"]);
        // Ambiguous: two driver types, or one setting written twice.
        assert_eq!(
            refusals(
                "driver_type: DRIVER_UDP\ndriver_cfg { driver_type: DRIVER_WHOI_MICROMODEM }\n",
                Layout::File
            ),
            ["b.moos:1:1: driver_type"]
        );
        assert_eq!(
            refusals(
                "driver_cfg {\n  udp { max_frame_size: 1 }\n  [UDPDriverConfig.max_frame_size]: 2\n}\n",
                Layout::File
            ),
            ["b.moos:3:3: driver_cfg.[UDPDriverConfig.max_frame_size]"]
        );
        // A problem found later with the Goby 2 setting is placed on it.
        let places = super::super::Places::new(
            "driver_cfg {\n  [UDPDriverConfig.remote] { port: 1 }\n}\n",
            Vec::new(),
        );
        assert_eq!(places.offset("driver.udp.remote[0].port"), Some(42));
    }

    #[test]
    fn moos_lines_of_a_block_are_read_or_refused() {
        let text = "  AppTick = 4\n  CommsTick = 4   # mail\n  MODEM_ID = 3\n  load_proto_file = nav.proto\n  modem_id_lookup_path = \"ids.txt\"\n  mac { type: MAC_NONE }\n";
        let read = read(text, "b.moos", Layout::MissionBlock).unwrap();
        assert_eq!(read.config.modem_id(), 3);
        assert_eq!(read.config.dccl.as_ref().unwrap().proto_file, ["nav.proto"]);
        assert_eq!(read.config.modem_id_lookup_path(), "ids.txt");
        assert_eq!(read.notes.len(), 1);
        let note = &read.notes[0];
        assert_eq!(note.level, NoteLevel::Info);
        assert!(
            note.to_string().starts_with(
                "b.moos:1:3: AppTick (line 1), CommsTick (line 2): MOOS application settings"
            ),
            "{note}"
        );
        // A problem found later of a field set on a MOOS line is placed there.
        let mut problems = vec![super::super::Problem::new("modem_id", "x")];
        read.locate(&mut problems);
        assert_eq!(problems[0].place.as_deref(), Some("b.moos:3:3"));
        assert_eq!(
            refusals(
                "  modem_id: 1\n  Frobnicate = 2\n  mac = 3\n  data_dir = a\n  data_dir = b\n  modem_id = 2\n  duplicate_window_seconds = soon\n",
                Layout::MissionBlock
            ),
            [
                "b.moos:2:3: Frobnicate",
                "b.moos:3:3: mac",
                "b.moos:5:3: data_dir",
                "b.moos:6:3: modem_id",
                "b.moos:7:30: duplicate_window_seconds",
            ]
        );
    }
}
