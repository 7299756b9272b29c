//! Typed access to the fields of a Micro-Modem sentence ([`Fields`]), and
//! why a line is not a sentence ([`SentenceError`]): shared by the
//! sentences and their statistics.

use super::nmea::{NmeaError, NmeaSentence};

/// Why a line is not a Micro-Modem sentence.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SentenceError {
    /// Not NMEA (including a checksum mismatch).
    #[error(transparent)]
    Nmea(#[from] NmeaError),
    /// An address this implementation does not know.
    #[error("unknown sentence ${0}")]
    Unknown(String),
    /// A field missing or malformed.
    #[error("${sentence} field {field} ({name}): {problem}")]
    Field {
        /// The sentence address.
        sentence: String,
        /// Field index (1 is the first after the address).
        field: usize,
        /// Field name.
        name: &'static str,
        /// What is wrong.
        problem: String,
    },
}

/// Bytes written as hex digits, two a byte.
pub(super) fn hex_decode(text: &str) -> Option<Vec<u8>> {
    if !text.len().is_multiple_of(2) {
        return None;
    }
    text.as_bytes()
        .chunks(2)
        .map(|pair| {
            let s = std::str::from_utf8(pair).ok()?;
            u8::from_str_radix(s, 16).ok()
        })
        .collect()
}

/// Typed access to a sentence's fields; errors name the sentence and field.
pub(super) struct Fields<'a> {
    pub(super) sentence: &'a NmeaSentence,
}

impl Fields<'_> {
    pub(super) fn err(
        &self,
        i: usize,
        name: &'static str,
        problem: impl Into<String>,
    ) -> SentenceError {
        SentenceError::Field {
            sentence: self.sentence.address(),
            field: i + 1,
            name,
            problem: problem.into(),
        }
    }

    pub(super) fn text(&self, i: usize, name: &'static str) -> Result<String, SentenceError> {
        self.sentence
            .field(i)
            .map(str::to_string)
            .ok_or_else(|| self.err(i, name, "missing"))
    }

    pub(super) fn uint(&self, i: usize, name: &'static str) -> Result<u32, SentenceError> {
        let t = self.text(i, name)?;
        t.trim()
            .parse()
            .map_err(|_| self.err(i, name, format!("{t:?} is not an unsigned integer")))
    }

    pub(super) fn int(&self, i: usize, name: &'static str) -> Result<i32, SentenceError> {
        let t = self.text(i, name)?;
        t.trim()
            .parse()
            .map_err(|_| self.err(i, name, format!("{t:?} is not an integer")))
    }

    pub(super) fn opt_float(
        &self,
        i: usize,
        name: &'static str,
    ) -> Result<Option<f64>, SentenceError> {
        match self.sentence.field(i).map(str::trim) {
            None | Some("") => Ok(None),
            Some(_) => self.float(i, name).map(Some),
        }
    }

    pub(super) fn flag(&self, i: usize, name: &'static str) -> Result<bool, SentenceError> {
        match self.uint(i, name)? {
            0 => Ok(false),
            1 => Ok(true),
            v => Err(self.err(i, name, format!("{v} is neither 0 nor 1"))),
        }
    }

    pub(super) fn float(&self, i: usize, name: &'static str) -> Result<f64, SentenceError> {
        let t = self.text(i, name)?;
        match t.trim().parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.err(i, name, format!("{t:?} is not a number"))),
        }
    }

    pub(super) fn hex(&self, i: usize, name: &'static str) -> Result<Vec<u8>, SentenceError> {
        let t = self.text(i, name)?;
        hex_decode(&t).ok_or_else(|| self.err(i, name, format!("{t:?} is not hex bytes")))
    }
}
