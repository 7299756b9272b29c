//! Reading the `(dccl.msg)` and `(dccl.field)` options from descriptors.

use prost::Message;
use prost_reflect::{DynamicMessage, FieldDescriptor, MessageDescriptor, ReflectMessage, Value};
use protos::dccl::{DcclFieldOptions, DcclMessageOptions};

use crate::error::CodecError;

fn extension<T: Message + Default>(
    options: &DynamicMessage,
    pool: &prost_reflect::DescriptorPool,
    name: &str,
) -> Result<T, CodecError> {
    let Some(ext) = pool.get_extension_by_name(name) else {
        return Ok(T::default());
    };
    if !options.has_extension(&ext) {
        return Ok(T::default());
    }
    match options.get_extension(&ext).as_ref() {
        Value::Message(m) => T::decode(m.encode_to_vec().as_slice())
            .map_err(|e| CodecError::new(format!("cannot read ({name}) options: {e}"))),
        _ => Ok(T::default()),
    }
}

/// The `(dccl.field)` options of a field (all unset when it has none).
pub fn field_options(field: &FieldDescriptor) -> Result<DcclFieldOptions, CodecError> {
    extension(&field.options(), field.parent_pool(), "dccl.field")
}

/// The `(dccl.msg)` options of a message (all unset when it has none).
pub fn message_options(desc: &MessageDescriptor) -> Result<DcclMessageOptions, CodecError> {
    extension(&desc.options(), desc.parent_pool(), "dccl.msg")
}

/// True when the message carries a `(dccl.msg)` option at all.
pub fn has_message_options(desc: &MessageDescriptor) -> bool {
    let Some(ext) = desc.parent_pool().get_extension_by_name("dccl.msg") else {
        return false;
    };
    desc.options().has_extension(&ext)
}

/// The `(dccl.field)` options of a field as a dynamic message, with the
/// codec-specific extensions of `dccl.DCCLFieldOptions` (`None` when unset).
pub fn raw_field_options(field: &FieldDescriptor) -> Option<DynamicMessage> {
    let ext = field.parent_pool().get_extension_by_name("dccl.field")?;
    let options = field.options();
    if !options.has_extension(&ext) {
        return None;
    }
    match options.get_extension(&ext).as_ref() {
        Value::Message(m) => Some(m.clone()),
        _ => None,
    }
}

/// A codec-specific extension of `dccl.DCCLFieldOptions` set on a field,
/// by the extension's full name (e.g. `arithmetic`, `goby.dccl.delta`).
pub fn field_option_extension(field: &FieldDescriptor, full_name: &str) -> Option<DynamicMessage> {
    let options = raw_field_options(field)?;
    let ext = options
        .descriptor()
        .parent_pool()
        .get_extension_by_name(full_name)?;
    if !options.has_extension(&ext) {
        return None;
    }
    match options.get_extension(&ext).as_ref() {
        Value::Message(m) => Some(m.clone()),
        _ => None,
    }
}
