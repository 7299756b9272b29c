//! One MOOS message: its kinds, data types, and byte layout.
//!
//! Layout (little-endian): `i32` total length of the message including this field,
//! `i32` id, `u8` message kind, `u8` data type, then the strings source, source aux,
//! originating community and key, then the doubles time, value and aux value, and
//! last the string value. Every string is an `i32` length followed by its bytes.

use super::WireError;

/// Handshake key by which a client declares it can take unsolicited mail pushed by the DB.
pub const HANDSHAKE_KEY_ASYNCHRONOUS: &str = "asynchronous";

/// Smallest possible encoded message: all fixed fields and five empty strings.
const MIN_MESSAGE_LEN: usize = 4 + 4 + 1 + 1 + 4 * 5 + 8 * 3;

/// What a message asks for or announces (the message type byte).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MessageKind {
    /// `N`: a variable was written.
    Notify,
    /// `R`: subscribe to a variable; the double value is the minimum interval in seconds.
    Register,
    /// `U`: unsubscribe from a variable.
    Unregister,
    /// `*`: subscribe by variable and application patterns.
    WildcardRegister,
    /// `/`: unsubscribe by patterns.
    WildcardUnregister,
    /// `~`: not set.
    NotSet,
    /// `C`: command.
    Command,
    /// `A`: anonymous.
    Anonymous,
    /// `.`: empty message; legacy DBs put one carrying their time at the front of each reply.
    Null,
    /// `i`: data; the client's handshake message (key: handshake key, string: client name).
    Data,
    /// `K`: the DB refuses the client; the string value says why.
    Poison,
    /// `W`: the DB welcomes the client after a handshake.
    Welcome,
    /// `Q`: a request to the server.
    ServerRequest,
    /// `T`: timing message; asynchronous clients send one periodically as a heartbeat.
    Timing,
    /// `^`: terminate connection (used inside clients, not normally on the wire).
    TerminateConnection,
}

impl MessageKind {
    /// The type byte on the wire.
    pub fn to_byte(self) -> u8 {
        match self {
            MessageKind::Notify => b'N',
            MessageKind::Register => b'R',
            MessageKind::Unregister => b'U',
            MessageKind::WildcardRegister => b'*',
            MessageKind::WildcardUnregister => b'/',
            MessageKind::NotSet => b'~',
            MessageKind::Command => b'C',
            MessageKind::Anonymous => b'A',
            MessageKind::Null => b'.',
            MessageKind::Data => b'i',
            MessageKind::Poison => b'K',
            MessageKind::Welcome => b'W',
            MessageKind::ServerRequest => b'Q',
            MessageKind::Timing => b'T',
            MessageKind::TerminateConnection => b'^',
        }
    }

    /// The kind for a type byte.
    pub fn from_byte(byte: u8) -> Result<Self, WireError> {
        Ok(match byte {
            b'N' => MessageKind::Notify,
            b'R' => MessageKind::Register,
            b'U' => MessageKind::Unregister,
            b'*' => MessageKind::WildcardRegister,
            b'/' => MessageKind::WildcardUnregister,
            b'~' => MessageKind::NotSet,
            b'C' => MessageKind::Command,
            b'A' => MessageKind::Anonymous,
            b'.' => MessageKind::Null,
            b'i' => MessageKind::Data,
            b'K' => MessageKind::Poison,
            b'W' => MessageKind::Welcome,
            b'Q' => MessageKind::ServerRequest,
            b'T' => MessageKind::Timing,
            b'^' => MessageKind::TerminateConnection,
            other => return Err(WireError::UnknownMessageKind(other)),
        })
    }
}

/// Which value field of a message is meaningful (the data type byte).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DataType {
    /// `D`: the double value.
    Double,
    /// `S`: the string value, as text.
    String,
    /// `B`: the string value, as arbitrary bytes.
    Binary,
}

impl DataType {
    /// The data type byte on the wire.
    pub fn to_byte(self) -> u8 {
        match self {
            DataType::Double => b'D',
            DataType::String => b'S',
            DataType::Binary => b'B',
        }
    }

    /// The data type for a byte.
    pub fn from_byte(byte: u8) -> Result<Self, WireError> {
        match byte {
            b'D' => Ok(DataType::Double),
            b'S' => Ok(DataType::String),
            b'B' => Ok(DataType::Binary),
            other => Err(WireError::UnknownDataType(other)),
        }
    }
}

/// The value a notification carries, as its data type says.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// A double.
    Double(f64),
    /// UTF-8 text.
    String(String),
    /// Arbitrary bytes.
    Binary(Vec<u8>),
}

/// One MOOS message with every field the wire carries.
///
/// Fields are kept as sent, whatever the data type, so that decoding and encoding are
/// lossless: for example the DB's welcome message is of double type but also carries
/// a string value, and timing messages use both doubles.
#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    /// Message id; clients number their messages, server requests use -2, others -1.
    pub id: i32,
    /// What the message is.
    pub kind: MessageKind,
    /// Which value field is meaningful.
    pub data_type: DataType,
    /// Name of the client that sent it.
    pub source: String,
    /// Extra source information.
    pub source_aux: String,
    /// Community the message originated in (filled in by the DB).
    pub community: String,
    /// Variable name (or, for the handshake, the handshake key).
    pub key: String,
    /// Time stamp, seconds since the Unix epoch.
    pub time: f64,
    /// Double value.
    pub double: f64,
    /// Second double value (timing messages: the DB's requested outgoing delay, s).
    pub double_aux: f64,
    /// String value, as bytes (text for [`DataType::String`]).
    pub string: Vec<u8>,
}

impl Message {
    /// A message of `kind` about `key` with every other field at the MOOS defaults
    /// (id and doubles -1, strings empty, double data type).
    pub fn new(kind: MessageKind, key: impl Into<String>, time: f64) -> Self {
        Message {
            id: -1,
            kind,
            data_type: DataType::Double,
            source: String::new(),
            source_aux: String::new(),
            community: String::new(),
            key: key.into(),
            time,
            double: -1.0,
            double_aux: -1.0,
            string: Vec::new(),
        }
    }

    /// A notification that `key` now holds the text `value`.
    pub fn notify_string(key: impl Into<String>, value: impl Into<String>, time: f64) -> Self {
        let mut m = Message::new(MessageKind::Notify, key, time);
        m.data_type = DataType::String;
        m.string = value.into().into_bytes();
        m
    }

    /// A notification that `key` now holds the double `value`.
    pub fn notify_double(key: impl Into<String>, value: f64, time: f64) -> Self {
        let mut m = Message::new(MessageKind::Notify, key, time);
        m.double = value;
        m
    }

    /// A notification that `key` now holds the bytes `value`.
    pub fn notify_binary(key: impl Into<String>, value: impl Into<Vec<u8>>, time: f64) -> Self {
        let mut m = Message::new(MessageKind::Notify, key, time);
        m.data_type = DataType::Binary;
        m.string = value.into();
        m
    }

    /// A subscription to `key`, to be told at most once per `interval_s` seconds (0: every write).
    pub fn register(key: impl Into<String>, interval_s: f64, time: f64) -> Self {
        let mut m = Message::new(MessageKind::Register, key, time);
        m.double = interval_s;
        m
    }

    /// Cancels a subscription to `key`.
    pub fn unregister(key: impl Into<String>, time: f64) -> Self {
        let mut m = Message::new(MessageKind::Unregister, key, time);
        m.double = 0.0;
        m
    }

    /// The handshake a client sends after the preamble: its name, and the key
    /// [`HANDSHAKE_KEY_ASYNCHRONOUS`] to ask for pushed mail.
    pub fn handshake(client_name: impl Into<String>, time: f64) -> Self {
        let mut m = Message::new(MessageKind::Data, HANDSHAKE_KEY_ASYNCHRONOUS, time);
        m.data_type = DataType::String;
        m.string = client_name.into().into_bytes();
        m
    }

    /// A timing message (heartbeat) stamped with the sender's `time`.
    pub fn timing(time: f64) -> Self {
        let mut m = Message::new(MessageKind::Timing, "_async_timing", time);
        m.double = 0.0;
        m
    }

    /// The meaningful value, as the data type says; text that is not UTF-8 is an error.
    pub fn value(&self) -> Result<Value, WireError> {
        Ok(match self.data_type {
            DataType::Double => Value::Double(self.double),
            DataType::String => {
                Value::String(String::from_utf8(self.string.clone()).map_err(|_| {
                    WireError::InvalidUtf8 {
                        field: "string value",
                    }
                })?)
            }
            DataType::Binary => Value::Binary(self.string.clone()),
        })
    }

    /// The string value as text, if it is valid UTF-8.
    pub fn string_text(&self) -> Option<&str> {
        std::str::from_utf8(&self.string).ok()
    }

    /// Number of bytes [`Message::encode_into`] writes.
    pub fn encoded_len(&self) -> usize {
        MIN_MESSAGE_LEN
            + self.source.len()
            + self.source_aux.len()
            + self.community.len()
            + self.key.len()
            + self.string.len()
    }

    /// Appends the encoded message to `out`.
    pub fn encode_into(&self, out: &mut Vec<u8>) -> Result<(), WireError> {
        let total = self.encoded_len();
        let total_i32 = i32::try_from(total).map_err(|_| WireError::TooLong {
            field: "message",
            length: total,
        })?;
        out.reserve(total);
        out.extend_from_slice(&total_i32.to_le_bytes());
        out.extend_from_slice(&self.id.to_le_bytes());
        out.push(self.kind.to_byte());
        out.push(self.data_type.to_byte());
        for (field, bytes) in [
            ("source", self.source.as_bytes()),
            ("source aux", self.source_aux.as_bytes()),
            ("community", self.community.as_bytes()),
            ("key", self.key.as_bytes()),
        ] {
            put_bytes(out, field, bytes)?;
        }
        for d in [self.time, self.double, self.double_aux] {
            out.extend_from_slice(&d.to_le_bytes());
        }
        put_bytes(out, "string value", &self.string)
    }

    /// Decodes one message from the front of `input`; returns it and the bytes it used.
    pub fn decode(input: &[u8]) -> Result<(Message, usize), WireError> {
        let mut whole = Reader::new(input);
        let declared = whole.length("message length")?;
        if declared < MIN_MESSAGE_LEN {
            return Err(WireError::MessageLength {
                declared,
                used: MIN_MESSAGE_LEN,
            });
        }
        if declared > input.len() {
            return Err(WireError::Truncated {
                field: "message",
                needed: declared,
                available: input.len(),
            });
        }
        let mut r = Reader::new(&input[..declared]);
        r.pos = 4;
        let id = r.i32("id")?;
        let kind = MessageKind::from_byte(r.u8("message type")?)?;
        let data_type = DataType::from_byte(r.u8("data type")?)?;
        let source = r.text("source")?;
        let source_aux = r.text("source aux")?;
        let community = r.text("community")?;
        let key = r.text("key")?;
        let time = r.f64("time")?;
        let double = r.f64("double value")?;
        let double_aux = r.f64("double aux value")?;
        let string = r.bytes("string value")?.to_vec();
        if r.pos != declared {
            return Err(WireError::MessageLength {
                declared,
                used: r.pos,
            });
        }
        Ok((
            Message {
                id,
                kind,
                data_type,
                source,
                source_aux,
                community,
                key,
                time,
                double,
                double_aux,
                string,
            },
            declared,
        ))
    }
}

fn put_bytes(out: &mut Vec<u8>, field: &'static str, bytes: &[u8]) -> Result<(), WireError> {
    let len = i32::try_from(bytes.len()).map_err(|_| WireError::TooLong {
        field,
        length: bytes.len(),
    })?;
    out.extend_from_slice(&len.to_le_bytes());
    out.extend_from_slice(bytes);
    Ok(())
}

/// Bounds-checked little-endian reading.
pub(super) struct Reader<'a> {
    input: &'a [u8],
    pub(super) pos: usize,
}

impl<'a> Reader<'a> {
    pub(super) fn new(input: &'a [u8]) -> Self {
        Reader { input, pos: 0 }
    }

    pub(super) fn remaining(&self) -> &'a [u8] {
        &self.input[self.pos..]
    }

    pub(super) fn take(&mut self, field: &'static str, n: usize) -> Result<&'a [u8], WireError> {
        let rest = self.remaining();
        if rest.len() < n {
            return Err(WireError::Truncated {
                field,
                needed: n,
                available: rest.len(),
            });
        }
        self.pos += n;
        Ok(&rest[..n])
    }

    pub(super) fn u8(&mut self, field: &'static str) -> Result<u8, WireError> {
        Ok(self.take(field, 1)?[0])
    }

    pub(super) fn i32(&mut self, field: &'static str) -> Result<i32, WireError> {
        let b = self.take(field, 4)?;
        Ok(i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    /// A non-negative `i32` length or count.
    pub(super) fn length(&mut self, field: &'static str) -> Result<usize, WireError> {
        let value = self.i32(field)?;
        usize::try_from(value).map_err(|_| WireError::Negative { field, value })
    }

    fn f64(&mut self, field: &'static str) -> Result<f64, WireError> {
        let b = self.take(field, 8)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(f64::from_le_bytes(a))
    }

    fn bytes(&mut self, field: &'static str) -> Result<&'a [u8], WireError> {
        let len = self.length(field)?;
        self.take(field, len)
    }

    fn text(&mut self, field: &'static str) -> Result<String, WireError> {
        let bytes = self.bytes(field)?;
        String::from_utf8(bytes.to_vec()).map_err(|_| WireError::InvalidUtf8 { field })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Message {
        let mut m = Message::notify_string("NAV_X", "hello", 1_700_000_000.25);
        m.id = 7;
        m.source = "pHelm".into();
        m.source_aux = "aux".into();
        m.community = "alpha".into();
        m
    }

    /// The layout written out by hand, independent of the encoder.
    fn sample_bytes() -> Vec<u8> {
        let mut b = Vec::new();
        let total: i32 = 4 + 4 + 1 + 1 + (4 + 5) + (4 + 3) + (4 + 5) + (4 + 5) + 24 + (4 + 5);
        b.extend_from_slice(&total.to_le_bytes());
        b.extend_from_slice(&7i32.to_le_bytes());
        b.push(b'N');
        b.push(b'S');
        for s in ["pHelm", "aux", "alpha", "NAV_X"] {
            b.extend_from_slice(&(s.len() as i32).to_le_bytes());
            b.extend_from_slice(s.as_bytes());
        }
        for d in [1_700_000_000.25f64, -1.0, -1.0] {
            b.extend_from_slice(&d.to_le_bytes());
        }
        b.extend_from_slice(&5i32.to_le_bytes());
        b.extend_from_slice(b"hello");
        b
    }

    #[test]
    fn encodes_the_documented_layout() {
        let mut out = Vec::new();
        sample().encode_into(&mut out).unwrap();
        assert_eq!(out, sample_bytes());
        assert_eq!(out.len(), sample().encoded_len());
    }

    #[test]
    fn decodes_what_it_encodes() {
        let bytes = sample_bytes();
        let (m, used) = Message::decode(&bytes).unwrap();
        assert_eq!(used, bytes.len());
        assert_eq!(m, sample());
        assert_eq!(m.value().unwrap(), Value::String("hello".into()));
    }

    #[test]
    fn every_truncation_is_an_error() {
        let bytes = sample_bytes();
        for n in 0..bytes.len() {
            assert!(Message::decode(&bytes[..n]).is_err(), "prefix of {n} bytes");
        }
    }

    #[test]
    fn errors_name_the_field() {
        let mut bytes = sample_bytes();
        // Claim the key is 1000 bytes long.
        let key_len_at = 4 + 4 + 2 + (4 + 5) + (4 + 3) + (4 + 5);
        bytes[key_len_at..key_len_at + 4].copy_from_slice(&1000i32.to_le_bytes());
        let err = Message::decode(&bytes).unwrap_err();
        assert!(
            matches!(err, WireError::Truncated { field: "key", .. }),
            "{err}"
        );

        let mut bytes = sample_bytes();
        bytes[8] = b'?';
        assert_eq!(
            Message::decode(&bytes).unwrap_err(),
            WireError::UnknownMessageKind(b'?')
        );

        let mut bytes = sample_bytes();
        bytes[key_len_at..key_len_at + 4].copy_from_slice(&(-3i32).to_le_bytes());
        assert_eq!(
            Message::decode(&bytes).unwrap_err(),
            WireError::Negative {
                field: "key",
                value: -3
            }
        );
    }

    #[test]
    fn length_prefix_must_match_the_fields() {
        let mut bytes = sample_bytes();
        let longer = bytes.len() as i32 + 2;
        bytes[..4].copy_from_slice(&longer.to_le_bytes());
        bytes.extend_from_slice(&[0, 0]);
        assert!(matches!(
            Message::decode(&bytes).unwrap_err(),
            WireError::MessageLength { .. }
        ));
    }

    #[test]
    fn invalid_utf8_text_is_reported() {
        let mut m = Message::notify_binary("RAW", vec![0xff, 0xfe], 0.0);
        assert_eq!(m.value().unwrap(), Value::Binary(vec![0xff, 0xfe]));
        m.data_type = DataType::String;
        assert_eq!(
            m.value().unwrap_err(),
            WireError::InvalidUtf8 {
                field: "string value"
            }
        );
    }
}
