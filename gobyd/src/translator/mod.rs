//! The MOOS translator, as pAcommsHandler's and pTranslator's: it makes a
//! DCCL message from MOOS variables when a trigger fires and writes a
//! received message to MOOS variables, as each `translator_entry`
//! (`goby.moos.protobuf.TranslatorEntry`) of the configuration says.
//!
//! The translator works on values, not connections: [`Translator::create`]
//! takes the latest value of each variable, [`Translator::publish`] returns
//! the variables and values to write, so it is usable without `gobyd`'s
//! runtime (the daemon's MOOS bridge drives it in `gobyd`).
//!
//! Modules: [`technique`] (protobuf text and encodings, prefixed or not),
//! [`key_value`] (`KEY=value,...`), [`format`](mod@format) (`%N%` format strings),
//! [`field_text`] (a field's value as text), [`algorithm`] (the
//! algorithms), [`local_grid`] (the mission's local grid) and
//! [`modem_id`] (the modem-id lookup file).

pub mod algorithm;
pub mod field_text;
pub mod format;
pub mod key_value;
pub mod local_grid;
pub mod modem_id;
pub mod technique;

use std::collections::{BTreeSet, HashMap};
use std::time::Duration;

use moos::Value as MoosValue;
use prost_reflect::{DynamicMessage, MessageDescriptor, ReflectMessage};
use protos::goby::moos::protobuf::translator_entry::{
    trigger, ParserSerializerTechnique as Technique,
};
use protos::goby::moos::protobuf::TranslatorEntry;

pub use algorithm::Algorithms;

/// A value that could not be translated: the message type, the variable,
/// its value and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{protobuf_name}: {variable} = {value:?}: {reason}")]
pub struct TranslateError {
    /// The DCCL type being made or written.
    pub protobuf_name: String,
    /// The MOOS variable.
    pub variable: String,
    /// Its value (text; bytes in hexadecimal).
    pub value: String,
    /// Why it could not be translated.
    pub reason: String,
}

/// The text of a MOOS value: a string as it is, a double with 15
/// significant digits, bytes in hexadecimal.
pub fn value_text(value: &MoosValue) -> String {
    match value {
        MoosValue::String(s) => s.clone(),
        MoosValue::Double(d) => field_text::format_double(*d),
        MoosValue::Binary(b) => match std::str::from_utf8(b) {
            Ok(s) => s.to_string(),
            Err(_) => hex::encode(b),
        },
    }
}

/// The translator entries of a configuration, checked, with their types.
#[derive(Debug)]
pub struct Translator {
    entries: Vec<(TranslatorEntry, MessageDescriptor)>,
    library: Algorithms,
}

fn technique(raw: Option<i32>) -> Technique {
    raw.and_then(|t| Technique::try_from(t).ok())
        .unwrap_or(Technique::TechniqueProtobufTextFormat)
}

impl Translator {
    /// Checks `entries` and finds their types with `lookup` (a DCCL type's
    /// descriptor by full name). Errors name the entry and the field: a
    /// type not loaded, two entries for one type, a trigger without its
    /// variable or period, a format technique without a format, an unknown
    /// algorithm, a publish algorithm naming no singular field.
    pub fn new(
        entries: &[TranslatorEntry],
        lookup: impl Fn(&str) -> Option<MessageDescriptor>,
        library: Algorithms,
    ) -> Result<Self, String> {
        let mut checked: Vec<(TranslatorEntry, MessageDescriptor)> = Vec::new();
        for entry in entries {
            let name = &entry.protobuf_name;
            let at = format!("translator_entry {name}");
            if checked.iter().any(|(e, _)| &e.protobuf_name == name) {
                return Err(format!("{at}: a second entry for the same type"));
            }
            let desc =
                lookup(name).ok_or_else(|| format!("{at}: {name} is not a loaded DCCL type"))?;
            if let Some(t) = &entry.trigger {
                match t.r#type() {
                    trigger::Type::TriggerPublish if t.moos_var().is_empty() => {
                        return Err(format!("{at}: trigger of TRIGGER_PUBLISH needs moos_var"))
                    }
                    trigger::Type::TriggerTime if t.period() == 0 => {
                        return Err(format!(
                            "{at}: trigger of TRIGGER_TIME needs a period of 1 s or more"
                        ))
                    }
                    _ => {}
                }
            }
            for (i, c) in entry.create.iter().enumerate() {
                let at = format!("{at}: create {} ({})", i + 1, c.moos_var);
                if technique(c.technique) == Technique::TechniqueFormat && c.format.is_none() {
                    return Err(format!("{at}: TECHNIQUE_FORMAT needs format"));
                }
                for a in &c.algorithm {
                    if !Algorithms::is_known(&a.name) {
                        return Err(format!("{at}: unknown algorithm {:?}", a.name));
                    }
                }
            }
            for (i, p) in entry.publish.iter().enumerate() {
                let at = format!("{at}: publish {} ({})", i + 1, p.moos_var);
                if technique(p.technique) == Technique::TechniqueFormat && p.format.is_none() {
                    return Err(format!("{at}: TECHNIQUE_FORMAT needs format"));
                }
                for a in &p.algorithm {
                    if !Algorithms::is_known(&a.name) {
                        return Err(format!("{at}: unknown algorithm {:?}", a.name));
                    }
                    for number in std::iter::once(&a.primary_field).chain(&a.reference_field) {
                        let singular = u32::try_from(*number)
                            .ok()
                            .and_then(|n| desc.get_field(n))
                            .is_some_and(|f| !f.is_list());
                        if !singular {
                            return Err(format!(
                                "{at}: algorithm {}: field {number} is not a singular field of {name}",
                                a.name
                            ));
                        }
                    }
                }
            }
            checked.push((entry.clone(), desc));
        }
        Ok(Translator {
            entries: checked,
            library,
        })
    }

    /// The entries, in the configuration's order.
    pub fn entries(&self) -> impl Iterator<Item = &TranslatorEntry> {
        self.entries.iter().map(|(e, _)| e)
    }

    fn entry(&self, name: &str) -> Option<&(TranslatorEntry, MessageDescriptor)> {
        self.entries.iter().find(|(e, _)| e.protobuf_name == name)
    }

    /// Whether a type has an entry.
    pub fn has_entry(&self, name: &str) -> bool {
        self.entry(name).is_some()
    }

    /// Every variable the translator reads: triggers and create variables.
    pub fn variables(&self) -> BTreeSet<String> {
        let mut vars = BTreeSet::new();
        for (e, _) in &self.entries {
            if let Some(t) = &e.trigger {
                if t.r#type() == trigger::Type::TriggerPublish && !t.moos_var().is_empty() {
                    vars.insert(t.moos_var().to_string());
                }
            }
            vars.extend(e.create.iter().map(|c| c.moos_var.clone()));
        }
        vars
    }

    /// The types whose trigger fires on this write of `variable`: a
    /// TRIGGER_PUBLISH of the variable whose `mandatory_content`, if any,
    /// the value contains.
    pub fn triggered(&self, variable: &str, value: &MoosValue) -> Vec<&str> {
        let text = value_text(value);
        self.entries
            .iter()
            .filter(|(e, _)| {
                e.trigger.as_ref().is_some_and(|t| {
                    t.r#type() == trigger::Type::TriggerPublish
                        && t.moos_var() == variable
                        && t.mandatory_content
                            .as_deref()
                            .is_none_or(|m| text.contains(m))
                })
            })
            .map(|(e, _)| e.protobuf_name.as_str())
            .collect()
    }

    /// The types made every `period`: (type, period).
    pub fn timed(&self) -> Vec<(&str, Duration)> {
        self.entries
            .iter()
            .filter_map(|(e, _)| {
                let t = e.trigger.as_ref()?;
                (t.r#type() == trigger::Type::TriggerTime).then(|| {
                    (
                        e.protobuf_name.as_str(),
                        Duration::from_secs(t.period().into()),
                    )
                })
            })
            .collect()
    }

    /// Makes a message of type `name` from the latest value of each
    /// variable (`values`); parsers whose variable has not been written
    /// are skipped.
    pub fn create(
        &self,
        name: &str,
        values: &HashMap<String, MoosValue>,
    ) -> Result<DynamicMessage, TranslateError> {
        let Some((entry, desc)) = self.entry(name) else {
            return Err(TranslateError {
                protobuf_name: name.into(),
                variable: String::new(),
                value: String::new(),
                reason: "no translator_entry for this type".into(),
            });
        };
        let mut message = DynamicMessage::new(desc.clone());
        for parser in &entry.create {
            let Some(value) = values.get(&parser.moos_var) else {
                continue;
            };
            let fail = |reason: String| TranslateError {
                protobuf_name: name.into(),
                variable: parser.moos_var.clone(),
                value: value_text(value),
                reason,
            };
            let t = technique(parser.technique);
            match t {
                Technique::TechniqueCommaSeparatedKeyEqualsValuePairs => key_value::parse(
                    &value_text(value),
                    &mut message,
                    &parser.algorithm,
                    &self.library,
                    entry.use_short_enum(),
                )
                .map_err(fail)?,
                Technique::TechniqueFormat => format::parse(
                    &value_text(value),
                    &mut message,
                    parser.format(),
                    parser.repeated_delimiter(),
                    &parser.algorithm,
                    &self.library,
                    entry.use_short_enum(),
                )
                .map_err(fail)?,
                t => {
                    // Later parsers overwrite the fields they set.
                    let parsed = technique::parse(t, value, desc).map_err(fail)?;
                    for (field, v) in parsed.fields() {
                        message.set_field(&field, v.clone());
                    }
                }
            }
        }
        Ok(message)
    }

    /// The variables and values a received message is written to (none
    /// for a type without an entry). A format or key=value text that reads
    /// as a number is written as a double, as Goby does (Goby does so for
    /// every technique; hexadecimal here stays a string so that it reads
    /// back unchanged).
    pub fn publish(
        &self,
        message: &DynamicMessage,
    ) -> Result<Vec<(String, MoosValue)>, TranslateError> {
        let name = message.descriptor().full_name().to_string();
        let Some((entry, _)) = self.entry(&name) else {
            return Ok(Vec::new());
        };
        let mut out = Vec::new();
        for serializer in &entry.publish {
            let fail = |reason: String| TranslateError {
                protobuf_name: name.clone(),
                variable: serializer.moos_var.clone(),
                value: dccl::short_debug_string(message),
                reason,
            };
            let short = entry.use_short_enum();
            let mut variable = serializer.moos_var.clone();
            let value = match technique(serializer.technique) {
                Technique::TechniqueCommaSeparatedKeyEqualsValuePairs => MoosValue::String(
                    key_value::serialize(message, &serializer.algorithm, &self.library, short)
                        .map_err(fail)?,
                ),
                Technique::TechniqueFormat => {
                    variable = format::serialize(
                        message,
                        &serializer.moos_var,
                        serializer.repeated_delimiter(),
                        &serializer.algorithm,
                        &self.library,
                        short,
                    )
                    .map_err(fail)?;
                    MoosValue::String(
                        format::serialize(
                            message,
                            serializer.format(),
                            serializer.repeated_delimiter(),
                            &serializer.algorithm,
                            &self.library,
                            short,
                        )
                        .map_err(fail)?,
                    )
                }
                t => technique::serialize(t, message),
            };
            let textual = matches!(
                technique(serializer.technique),
                Technique::TechniqueFormat | Technique::TechniqueCommaSeparatedKeyEqualsValuePairs
            );
            let value = match value {
                MoosValue::String(s) if textual => match s.parse::<f64>() {
                    Ok(d) if s.trim() == s && !s.is_empty() => MoosValue::Double(d),
                    _ => MoosValue::String(s),
                },
                other => other,
            };
            out.push((variable, value));
        }
        Ok(out)
    }
}

/// The translator of a `gobyd` configuration: its `translator_entry`
/// blocks, with the local grid of `moos.lat_origin` / `moos.lon_origin`
/// and the lookup file `modem_id_lookup_path` when given. Types come from
/// `codec` (the loaded DCCL types).
pub fn from_config(
    config: &protos::goby::apps::protobuf::GobydConfig,
    codec: &dccl::Codec,
) -> Result<Translator, String> {
    let mut library = Algorithms::new();
    if let Some(moos) = &config.moos {
        if let (Some(lat), Some(lon)) = (moos.lat_origin, moos.lon_origin) {
            library = library.with_local_grid(
                local_grid::LocalGrid::new(lat, lon)
                    .map_err(|e| format!("moos.lat_origin, lon_origin: {e}"))?,
            );
        }
    }
    if let Some(path) = config
        .modem_id_lookup_path
        .as_deref()
        .filter(|p| !p.is_empty())
    {
        library = library.with_modem_ids(
            modem_id::ModemIdLookup::load(std::path::Path::new(path))
                .map_err(|e| format!("modem_id_lookup_path: {e}"))?,
        );
    }
    Translator::new(&config.translator_entry, |n| codec.descriptor(n), library)
}

#[cfg(test)]
mod tests;
