//! Roles: the source id, destination id and time of a queued message, taken
//! from named fields of the message (or fixed values) instead of a separate
//! header.

use prost_reflect::{
    DynamicMessage, FieldDescriptor, Kind, MessageDescriptor, ReflectMessage, Value,
};
use protos::goby::acomms::protobuf::queued_message_entry::{role::RoleSetting, Role, RoleType};

use crate::clock::{seconds_to_micros, Micros};
use crate::error::{QueueError, Result};

/// Where one role's value comes from.
#[derive(Debug, Clone)]
enum RoleSource {
    /// A field, reached through a path of (non-repeated) sub-message fields.
    Field {
        path: Vec<FieldDescriptor>,
        name: String,
    },
    /// A fixed value.
    Static(i64),
}

/// The roles configured for one message type.
#[derive(Debug, Clone, Default)]
pub(crate) struct Roles {
    source: Option<RoleSource>,
    destination: Option<RoleSource>,
    timestamp: Option<RoleSource>,
}

fn role_name(role: RoleType) -> &'static str {
    match role {
        RoleType::SourceId => "SOURCE_ID",
        RoleType::DestinationId => "DESTINATION_ID",
        RoleType::Timestamp => "TIMESTAMP",
    }
}

impl Roles {
    /// Resolves the configured roles against the message definition.
    pub(crate) fn resolve(desc: &MessageDescriptor, roles: &[Role]) -> Result<Self> {
        let mut out = Roles::default();
        for role in roles {
            let kind = role.r#type();
            let config_error = |reason: String| QueueError::Config {
                message: desc.full_name().to_string(),
                reason: format!("{} role: {reason}", role_name(kind)),
            };
            let source = match role.setting() {
                RoleSetting::Static => {
                    if kind == RoleType::Timestamp {
                        return Err(config_error(
                            "a time must come from a field, not a static value".into(),
                        ));
                    }
                    let value = role
                        .static_value
                        .ok_or_else(|| config_error("STATIC role without static_value".into()))?;
                    RoleSource::Static(i64::from(value))
                }
                RoleSetting::FieldValue => {
                    let name = role
                        .field
                        .as_deref()
                        .filter(|f| !f.is_empty())
                        .ok_or_else(|| config_error("FIELD_VALUE role without field".into()))?;
                    let path = resolve_path(desc, name, kind).map_err(config_error)?;
                    RoleSource::Field {
                        path,
                        name: name.to_string(),
                    }
                }
            };
            let slot = match kind {
                RoleType::SourceId => &mut out.source,
                RoleType::DestinationId => &mut out.destination,
                RoleType::Timestamp => &mut out.timestamp,
            };
            if slot.is_some() {
                return Err(config_error("given twice".into()));
            }
            *slot = Some(source);
        }
        Ok(out)
    }

    /// Source id of `msg` (`None`: no role, or the field is not set).
    pub(crate) fn source(&self, msg: &DynamicMessage) -> Result<Option<i64>> {
        read_id(self.source.as_ref(), msg, "SOURCE_ID")
    }

    /// Destination id of `msg` (`None`: no role, or the field is not set).
    pub(crate) fn destination(&self, msg: &DynamicMessage) -> Result<Option<i64>> {
        read_id(self.destination.as_ref(), msg, "DESTINATION_ID")
    }

    /// Time of `msg` (`None`: no role, or the field is not set). Integer
    /// fields hold microseconds since the epoch, floating-point fields seconds.
    pub(crate) fn timestamp(&self, msg: &DynamicMessage) -> Result<Option<Micros>> {
        let Some(RoleSource::Field { path, name }) = &self.timestamp else {
            return Ok(None);
        };
        let Some(value) = read_field(path, msg) else {
            return Ok(None);
        };
        let micros = match value {
            Value::U64(v) => i64::try_from(v).ok(),
            Value::I64(v) => Some(v),
            Value::U32(v) => Some(i64::from(v)),
            Value::I32(v) => Some(i64::from(v)),
            Value::F64(v) if v.is_finite() => Some(seconds_to_micros(v)),
            Value::F32(v) if v.is_finite() => Some(seconds_to_micros(f64::from(v))),
            _ => None,
        };
        micros.map(Some).ok_or_else(|| QueueError::Role {
            message: msg.descriptor().full_name().to_string(),
            role: "TIMESTAMP",
            field: name.clone(),
            reason: "value is not a usable time".into(),
        })
    }
}

fn read_id(
    source: Option<&RoleSource>,
    msg: &DynamicMessage,
    role: &'static str,
) -> Result<Option<i64>> {
    match source {
        None => Ok(None),
        Some(RoleSource::Static(v)) => Ok(Some(*v)),
        Some(RoleSource::Field { path, name }) => {
            let Some(value) = read_field(path, msg) else {
                return Ok(None);
            };
            let id = match value {
                Value::I32(v) => Some(i64::from(v)),
                Value::I64(v) => Some(v),
                Value::U32(v) => Some(i64::from(v)),
                Value::U64(v) => i64::try_from(v).ok(),
                _ => None,
            };
            id.map(Some).ok_or_else(|| QueueError::Role {
                message: msg.descriptor().full_name().to_string(),
                role,
                field: name.clone(),
                reason: "value is not a modem id".into(),
            })
        }
    }
}

/// Value of the last field of `path`, `None` when it or a sub-message on the
/// way is not set.
fn read_field(path: &[FieldDescriptor], msg: &DynamicMessage) -> Option<Value> {
    let (last, parents) = path.split_last()?;
    let mut current = std::borrow::Cow::Borrowed(msg);
    for field in parents {
        if !current.has_field(field) {
            return None;
        }
        let next = match current.get_field(field).into_owned() {
            Value::Message(m) => m,
            _ => return None,
        };
        current = std::borrow::Cow::Owned(next);
    }
    if !current.has_field(last) {
        return None;
    }
    Some(current.get_field(last).into_owned())
}

fn resolve_path(
    desc: &MessageDescriptor,
    dotted: &str,
    role: RoleType,
) -> std::result::Result<Vec<FieldDescriptor>, String> {
    let mut path = Vec::new();
    let mut current = desc.clone();
    let parts: Vec<&str> = dotted.split('.').collect();
    for (i, part) in parts.iter().enumerate() {
        let field = current
            .get_field_by_name(part)
            .ok_or_else(|| format!("no field {part:?} in {}", current.full_name()))?;
        if field.is_list() || field.is_map() {
            return Err(format!("field {dotted}: a role cannot be a repeated field"));
        }
        let last = i + 1 == parts.len();
        match (last, field.kind()) {
            (false, Kind::Message(sub)) => current = sub,
            (false, _) => return Err(format!("field {part} of {dotted} is not a message")),
            (true, kind) => {
                let integer = matches!(
                    kind,
                    Kind::Int32
                        | Kind::Sint32
                        | Kind::Sfixed32
                        | Kind::Int64
                        | Kind::Sint64
                        | Kind::Sfixed64
                        | Kind::Uint32
                        | Kind::Fixed32
                        | Kind::Uint64
                        | Kind::Fixed64
                );
                let float = matches!(kind, Kind::Double | Kind::Float);
                let ok = match role {
                    RoleType::Timestamp => integer || float,
                    RoleType::SourceId | RoleType::DestinationId => integer,
                };
                if !ok {
                    return Err(format!(
                        "field {dotted} has type {kind:?}; expected {}",
                        if role == RoleType::Timestamp {
                            "an integer (microseconds) or a double (seconds)"
                        } else {
                            "an integer"
                        }
                    ));
                }
            }
        }
        path.push(field);
    }
    Ok(path)
}
