//! Reading the `(dccl.msg)` and `(dccl.field)` options from descriptors.

use prost::Message;
use prost_reflect::{DynamicMessage, FieldDescriptor, MessageDescriptor, Value};
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
