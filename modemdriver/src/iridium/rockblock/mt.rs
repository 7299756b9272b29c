//! RockBLOCK's MT endpoint: a mobile-terminated message sent by HTTP POST
//! to the web service (`https://rockblock.rock7.com/rockblock/MT`), which
//! queues it for the RockBLOCK's next SBD session (and rings it).
//!
//! ```text
//!  POST /rockblock/MT   application/x-www-form-urlencoded
//!    imei=300234010753370&username=U&password=P&data=<hex>[&flush=yes]
//!  200  OK,<mtId>                    queued, the service's MT id
//!  200  FAILED,<code>,<description>  refused (codes in [`ErrorCode`])
//! ```
//!
//! The request is also taken with the fields in the URL's query, as the
//! service's own example writes it; this toolkit sends them in the body
//! (as Goby3 does), so that the password does not sit in a URL.

use std::fmt;

/// One MT message for the web service.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MtRequest {
    /// The RockBLOCK's IMEI (15 digits).
    pub imei: String,
    /// The account's user name.
    pub username: String,
    /// The account's password.
    pub password: String,
    /// The message.
    pub data: Vec<u8>,
    /// Drop the MT messages already queued for the RockBLOCK first
    /// (`flush=yes`).
    pub flush: bool,
}

impl MtRequest {
    /// The form body (`application/x-www-form-urlencoded`), data in hex.
    pub fn to_form(&self) -> String {
        let mut fields = vec![
            ("imei", self.imei.clone()),
            ("username", self.username.clone()),
            ("password", self.password.clone()),
            ("data", hex::encode(&self.data)),
        ];
        if self.flush {
            fields.push(("flush", "yes".into()));
        }
        // Plain strings as pairs: serialising them cannot fail.
        serde_urlencoded::to_string(fields).unwrap_or_default()
    }

    /// The request in the fields of a form (the service's side): the
    /// fields as given (body, or query, or both: the body wins), or the
    /// error the service answers (16 with no data, 14 with data not hex,
    /// 11 with no IMEI; credentials are the caller's to check).
    pub fn from_fields(fields: &[(String, String)]) -> Result<MtRequest, ErrorCode> {
        let get = |name: &str| {
            fields
                .iter()
                .find(|(k, _)| k == name)
                .map(|(_, v)| v.as_str())
        };
        let imei = get("imei").unwrap_or_default().trim().to_string();
        let username = get("username").unwrap_or_default().to_string();
        let password = get("password").unwrap_or_default().to_string();
        if imei.is_empty() {
            return Err(ErrorCode::ImeiNotFound);
        }
        let data = match get("data") {
            None | Some("") => return Err(ErrorCode::NoData),
            Some(hex_text) => hex::decode(hex_text.trim()).map_err(|_| ErrorCode::BadHex)?,
        };
        let flush = get("flush").is_some_and(|f| f.eq_ignore_ascii_case("yes"));
        Ok(MtRequest {
            imei,
            username,
            password,
            data,
            flush,
        })
    }
}

/// The service's error codes (`FAILED,<code>,<description>`), from its
/// documentation; [`ErrorCode::Other`] keeps a code it does not list.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorCode {
    /// 10: invalid login credentials.
    InvalidCredentials,
    /// 11: no RockBLOCK with this IMEI on the account.
    ImeiNotFound,
    /// 12: the RockBLOCK has no line rental.
    NoLineRental,
    /// 13: the account has insufficient credit.
    InsufficientCredit,
    /// 14: the data could not be decoded from hex.
    BadHex,
    /// 15: the data is too long.
    DataTooLong,
    /// 16: no data.
    NoData,
    /// 99: system error.
    SystemError,
    /// A code the documentation does not list.
    Other(i32),
}

impl ErrorCode {
    /// The number on the wire.
    pub fn code(self) -> i32 {
        match self {
            ErrorCode::InvalidCredentials => 10,
            ErrorCode::ImeiNotFound => 11,
            ErrorCode::NoLineRental => 12,
            ErrorCode::InsufficientCredit => 13,
            ErrorCode::BadHex => 14,
            ErrorCode::DataTooLong => 15,
            ErrorCode::NoData => 16,
            ErrorCode::SystemError => 99,
            ErrorCode::Other(c) => c,
        }
    }

    /// The code of number `code`.
    pub fn from_code(code: i32) -> ErrorCode {
        match code {
            10 => ErrorCode::InvalidCredentials,
            11 => ErrorCode::ImeiNotFound,
            12 => ErrorCode::NoLineRental,
            13 => ErrorCode::InsufficientCredit,
            14 => ErrorCode::BadHex,
            15 => ErrorCode::DataTooLong,
            16 => ErrorCode::NoData,
            99 => ErrorCode::SystemError,
            c => ErrorCode::Other(c),
        }
    }

    /// The description the service gives with the code.
    pub fn description(self) -> &'static str {
        match self {
            ErrorCode::InvalidCredentials => "Invalid login credentials",
            ErrorCode::ImeiNotFound => "No RockBLOCK with this IMEI found on your account",
            ErrorCode::NoLineRental => "RockBLOCK has no line rental",
            ErrorCode::InsufficientCredit => "Your account has insufficient credit",
            ErrorCode::BadHex => "Could not decode hex data",
            ErrorCode::DataTooLong => "Data too long",
            ErrorCode::NoData => "No data",
            ErrorCode::SystemError => "System Error",
            ErrorCode::Other(_) => "unknown error",
        }
    }

    /// Whether the same request may pass later without anything changed
    /// here: a system error (99), or a code not listed. Credentials, IMEI,
    /// line rental, credit and the message itself need a person or a
    /// different message.
    pub fn may_pass_later(self) -> bool {
        matches!(self, ErrorCode::SystemError | ErrorCode::Other(_))
    }
}

impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.code(), self.description())
    }
}

/// The service's answer to an MT POST (the body of a 200 response).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MtReply {
    /// `OK,<mtId>`: queued.
    Queued {
        /// The service's MT message id.
        mt_id: u64,
    },
    /// `FAILED,<code>,<description>`: refused.
    Failed {
        /// The error.
        code: ErrorCode,
        /// The description as the service wrote it.
        text: String,
    },
}

impl MtReply {
    /// The body the service sends.
    pub fn to_body(&self) -> String {
        match self {
            MtReply::Queued { mt_id } => format!("OK,{mt_id}"),
            MtReply::Failed { code, text } => format!("FAILED,{},{text}", code.code()),
        }
    }

    /// The refusal of `code`, in the service's words.
    pub fn failed(code: ErrorCode) -> MtReply {
        MtReply::Failed {
            code,
            text: code.description().to_string(),
        }
    }

    /// Reads a body: `OK,<id>` or `FAILED,<code>,<text>` (the text may
    /// hold commas; surrounding white space is ignored).
    pub fn parse(body: &str) -> Result<MtReply, String> {
        let body = body.trim();
        let shown = || {
            let mut s: String = body.chars().take(80).collect();
            if body.chars().count() > 80 {
                s.push('…');
            }
            s
        };
        let mut parts = body.splitn(3, ',');
        match parts.next() {
            Some("OK") => {
                let id = parts.next().map(str::trim).unwrap_or_default();
                if parts.next().is_some() {
                    return Err(format!("{:?}: OK with more than an MT id", shown()));
                }
                id.parse()
                    .map(|mt_id| MtReply::Queued { mt_id })
                    .map_err(|_| format!("{:?}: the MT id {id:?} is not a number", shown()))
            }
            Some("FAILED") => {
                let code = parts.next().map(str::trim).unwrap_or_default();
                let code: i32 = code.parse().map_err(|_| {
                    format!("{:?}: the error code {code:?} is not a number", shown())
                })?;
                Ok(MtReply::Failed {
                    code: ErrorCode::from_code(code),
                    text: parts.next().unwrap_or_default().trim().to_string(),
                })
            }
            _ => Err(format!(
                "{:?} is neither OK,<id> nor FAILED,<code>,<text>",
                shown()
            )),
        }
    }
}

impl fmt::Display for MtReply {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MtReply::Queued { mt_id } => write!(f, "queued as MT id {mt_id}"),
            MtReply::Failed { code, text } => {
                write!(f, "refused with error {}", code.code())?;
                if text.is_empty() {
                    write!(f, " ({})", code.description())
                } else {
                    write!(f, " ({text})")
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_is_a_form_read_back_by_the_service() {
        let r = MtRequest {
            imei: "300234010753370".into(),
            username: "me@example.com".into(),
            password: "p&ss=word".into(),
            data: vec![0x00, 0xab, 0xff],
            flush: true,
        };
        let form = r.to_form();
        assert_eq!(
            form,
            "imei=300234010753370&username=me%40example.com&password=p%26ss%3Dword&data=00abff&flush=yes"
        );
        let fields: Vec<(String, String)> = serde_urlencoded::from_str(&form).unwrap();
        assert_eq!(MtRequest::from_fields(&fields).unwrap(), r);
        let no_flush = MtRequest { flush: false, ..r };
        assert!(!no_flush.to_form().contains("flush"));
    }

    #[test]
    fn the_service_refuses_what_its_documentation_says() {
        let f = |s: &str| -> Vec<(String, String)> { serde_urlencoded::from_str(s).unwrap() };
        assert_eq!(
            MtRequest::from_fields(&f("imei=300234010753370&username=a&password=b")),
            Err(ErrorCode::NoData)
        );
        assert_eq!(
            MtRequest::from_fields(&f("imei=300234010753370&data=zz")),
            Err(ErrorCode::BadHex)
        );
        assert_eq!(
            MtRequest::from_fields(&f("imei=300234010753370&data=abc")),
            Err(ErrorCode::BadHex)
        );
        assert_eq!(
            MtRequest::from_fields(&f("data=00")),
            Err(ErrorCode::ImeiNotFound)
        );
    }

    #[test]
    fn replies_read_and_written() {
        assert_eq!(
            MtReply::parse("OK,4114651\n"),
            Ok(MtReply::Queued { mt_id: 4114651 })
        );
        assert_eq!(
            MtReply::parse("FAILED,10,Invalid login credentials"),
            Ok(MtReply::Failed {
                code: ErrorCode::InvalidCredentials,
                text: "Invalid login credentials".into()
            })
        );
        assert_eq!(
            MtReply::parse("FAILED,42,a, b"),
            Ok(MtReply::Failed {
                code: ErrorCode::Other(42),
                text: "a, b".into()
            })
        );
        for bad in ["", "OK", "OK,x", "OK,1,2", "FAILED", "FAILED,x,y", "<html>"] {
            assert!(MtReply::parse(bad).is_err(), "{bad:?}");
        }
        for reply in [
            MtReply::Queued { mt_id: 7 },
            MtReply::failed(ErrorCode::DataTooLong),
            MtReply::failed(ErrorCode::SystemError),
        ] {
            assert_eq!(MtReply::parse(&reply.to_body()), Ok(reply));
        }
        for c in [10, 11, 12, 13, 14, 15, 16, 99, 5] {
            assert_eq!(ErrorCode::from_code(c).code(), c);
        }
        assert!(ErrorCode::SystemError.may_pass_later());
        assert!(!ErrorCode::InsufficientCredit.may_pass_later());
        assert_eq!(
            MtReply::failed(ErrorCode::NoLineRental).to_string(),
            "refused with error 12 (RockBLOCK has no line rental)"
        );
    }
}
