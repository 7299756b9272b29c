use crate::codec::LoadedMessage;
pub(crate) fn report(_l: &LoadedMessage) -> String { String::new() }
