//! NMEA-0183 sentences: `$` + address (talker and sentence id) + `,`-separated
//! fields + `*` + two hex digits of checksum (XOR of the bytes between `$`
//! and `*`).
//!
//! [`NmeaSentence::parse`] never panics, whatever the bytes.

use std::fmt;

/// Why a line is not an NMEA sentence.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NmeaError {
    /// Nothing but whitespace.
    #[error("empty line")]
    Empty,
    /// Bytes outside printable ASCII.
    #[error("byte 0x{byte:02x} at {at} is not printable ASCII")]
    NotAscii {
        /// The byte.
        byte: u8,
        /// Its index.
        at: usize,
    },
    /// No leading `$`.
    #[error("does not start with '$'")]
    NoStart,
    /// No `*hh` checksum.
    #[error("no '*' checksum")]
    NoChecksum,
    /// The checksum is not two hex digits.
    #[error("checksum {0:?} is not two hex digits")]
    BadChecksumDigits(String),
    /// The checksum does not match the sentence.
    #[error("checksum mismatch: sentence says {given:02X}, bytes give {computed:02X}")]
    ChecksumMismatch {
        /// Checksum written in the line.
        given: u8,
        /// Checksum of the bytes.
        computed: u8,
    },
    /// The address is not a 2-letter talker and a 3-letter sentence id.
    #[error("address {0:?} is not a talker and sentence id (e.g. CCCYC)")]
    BadAddress(String),
}

/// XOR of `body`'s bytes.
pub fn checksum(body: &[u8]) -> u8 {
    body.iter().fold(0, |acc, b| acc ^ b)
}

/// One NMEA sentence.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NmeaSentence {
    /// Talker, e.g. "CC" (host to modem) or "CA" (modem to host).
    pub talker: String,
    /// Sentence id, e.g. "CYC".
    pub id: String,
    /// Fields after the address.
    pub fields: Vec<String>,
}

impl NmeaSentence {
    /// A sentence from its parts.
    pub fn new(talker: &str, id: &str, fields: Vec<String>) -> Self {
        NmeaSentence {
            talker: talker.to_string(),
            id: id.to_string(),
            fields,
        }
    }

    /// Talker and id, e.g. "CCCYC".
    pub fn address(&self) -> String {
        format!("{}{}", self.talker, self.id)
    }

    /// Field `i` (0 is the first after the address).
    pub fn field(&self, i: usize) -> Option<&str> {
        self.fields.get(i).map(String::as_str)
    }

    /// Parses a line (without its delimiter; surrounding whitespace is ignored).
    pub fn parse(line: &[u8]) -> Result<NmeaSentence, NmeaError> {
        let start = line.iter().position(|b| !b.is_ascii_whitespace());
        let end = line.iter().rposition(|b| !b.is_ascii_whitespace());
        let (Some(start), Some(end)) = (start, end) else {
            return Err(NmeaError::Empty);
        };
        let line = &line[start..=end];
        if let Some(at) = line.iter().position(|b| !(0x20..0x7f).contains(b)) {
            return Err(NmeaError::NotAscii {
                byte: line[at],
                at: start + at,
            });
        }
        // Printable ASCII from here on: every byte index is a char boundary.
        let text = std::str::from_utf8(line).map_err(|_| NmeaError::NoStart)?;
        let Some(rest) = text.strip_prefix('$') else {
            return Err(NmeaError::NoStart);
        };
        let Some((body, sum)) = rest.rsplit_once('*') else {
            return Err(NmeaError::NoChecksum);
        };
        if sum.len() != 2 {
            return Err(NmeaError::BadChecksumDigits(sum.to_string()));
        }
        let given = u8::from_str_radix(sum, 16)
            .map_err(|_| NmeaError::BadChecksumDigits(sum.to_string()))?;
        let computed = checksum(body.as_bytes());
        if given != computed {
            return Err(NmeaError::ChecksumMismatch { given, computed });
        }
        let mut parts = body.split(',');
        let address = parts.next().unwrap_or("");
        if address.len() != 5 || !address.bytes().all(|b| b.is_ascii_alphanumeric()) {
            return Err(NmeaError::BadAddress(address.to_string()));
        }
        let (talker, id) = address.split_at(2);
        Ok(NmeaSentence::new(
            talker,
            id,
            parts.map(str::to_string).collect(),
        ))
    }
}

impl fmt::Display for NmeaSentence {
    /// The line, without delimiter: `$CCCYC,0,1,2,0,1,1*5A`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut body = self.address();
        for field in &self.fields {
            body.push(',');
            body.push_str(field);
        }
        write!(f, "${body}*{:02X}", checksum(body.as_bytes()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn parses_and_writes_with_checksums() {
        let s = NmeaSentence::new(
            "CC",
            "CYC",
            ["0", "1", "2", "0", "1", "1"].map(String::from).to_vec(),
        );
        let line = s.to_string();
        assert!(line.starts_with("$CCCYC,0,1,2,0,1,1*"));
        assert_eq!(NmeaSentence::parse(line.as_bytes()).unwrap(), s);
        // A known sentence: XOR of "GPGLL,5057.970,N,00146.110,E,142451,A" is 0x27.
        let gll = NmeaSentence::parse(b"$GPGLL,5057.970,N,00146.110,E,142451,A*27\r").unwrap();
        assert_eq!(gll.address(), "GPGLL");
        assert_eq!(gll.field(5), Some("A"));
    }

    #[test]
    fn rejects_each_kind_of_bad_line() {
        assert_eq!(NmeaSentence::parse(b"  "), Err(NmeaError::Empty));
        assert_eq!(NmeaSentence::parse(b"CCCYC*00"), Err(NmeaError::NoStart));
        assert_eq!(NmeaSentence::parse(b"$CCCYC,1"), Err(NmeaError::NoChecksum));
        assert!(matches!(
            NmeaSentence::parse(b"$CCCYC*0G"),
            Err(NmeaError::BadChecksumDigits(_))
        ));
        assert!(matches!(
            NmeaSentence::parse(b"$CCCYC*00"),
            Err(NmeaError::ChecksumMismatch { .. })
        ));
        assert!(matches!(
            NmeaSentence::parse(b"$CC\xffC*00"),
            Err(NmeaError::NotAscii { .. })
        ));
        let bad = format!("$CCCY*{:02X}", checksum(b"CCCY"));
        assert!(matches!(
            NmeaSentence::parse(bad.as_bytes()),
            Err(NmeaError::BadAddress(_))
        ));
    }

    proptest! {
        #[test]
        fn never_panics_on_random_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            let _ = NmeaSentence::parse(&bytes);
        }

        #[test]
        fn never_panics_on_near_sentences(body in "[$A-Z0-9,*.\\-]{0,60}", sum in "[0-9A-Fa-fxyz]{0,3}") {
            let _ = NmeaSentence::parse(format!("${body}*{sum}").as_bytes());
        }

        #[test]
        fn round_trips(fields in proptest::collection::vec("[A-Z0-9.\\-]{0,12}", 0..8)) {
            let s = NmeaSentence::new("CA", "RXD", fields);
            prop_assert_eq!(NmeaSentence::parse(s.to_string().as_bytes()).unwrap(), s);
        }
    }
}
