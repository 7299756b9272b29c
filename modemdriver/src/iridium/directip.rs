//! Iridium's DirectIP messages: SBD messages between the Iridium gateway
//! and a vendor's application over TCP (Iridium Short Burst Data Service
//! Developers Guide, DirectIP).
//!
//! Every message is a pre-header — protocol revision (1) and the length
//! of what follows (2 bytes) — then information elements (IEs), each an id
//! (1 byte), a length (2 bytes) and its content; numbers are big-endian.
//!
//! ```text
//!  MO (gateway → vendor, one connection per message):
//!    0x01 header    28 bytes: CDR reference u32, IMEI 15 ASCII digits, session status u8,
//!                             MOMSN u16, MTMSN u16, time of session u32 (Unix seconds)
//!    0x02 payload   the message (1–1960 bytes)
//!    0x03 location  11 bytes: flags u8, latitude degrees u8, thousandths of minutes u16,
//!                             longitude degrees u8, thousandths of minutes u16, CEP radius u32 (km)
//!  MT (vendor → gateway, then the confirmation back on the same connection):
//!    0x41 header    21 bytes: unique client message id u32, IMEI, disposition flags u16
//!    0x42 payload   the message (1–1890 bytes)
//!    0x44 confirmation 25 bytes: client message id u32, IMEI, auto id reference u32,
//!                             status i16 (> 0: place in the MT queue; 0: no payload, sent; < 0: refused)
//! ```
//!
//! Parsing never panics: a message cut short, an IE longer than the
//! message, a header of the wrong length are errors; IEs of other ids are
//! kept as they are.

use std::fmt;

/// The protocol revision of every DirectIP message.
pub const PROTOCOL_REVISION: u8 = 1;

/// Bytes of the pre-header.
pub const PRE_HEADER_BYTES: usize = 3;

/// IE ids.
pub mod iei {
    /// MO header.
    pub const MO_HEADER: u8 = 0x01;
    /// MO payload.
    pub const MO_PAYLOAD: u8 = 0x02;
    /// MO location.
    pub const MO_LOCATION: u8 = 0x03;
    /// MO confirmation (vendor → gateway, when the gateway asks for one).
    pub const MO_CONFIRMATION: u8 = 0x05;
    /// MT header.
    pub const MT_HEADER: u8 = 0x41;
    /// MT payload.
    pub const MT_PAYLOAD: u8 = 0x42;
    /// MT confirmation.
    pub const MT_CONFIRMATION: u8 = 0x44;
}

/// MT disposition flags.
pub mod disposition {
    /// Drop the MT messages queued for the IMEI before this one.
    pub const FLUSH_MT_QUEUE: u16 = 0x0001;
    /// Send a ring alert even with no message.
    pub const SEND_RING_ALERT: u16 = 0x0002;
}

/// MT confirmation statuses (below zero: the message was refused).
pub mod mt_status {
    /// The IMEI is not 15 digits.
    pub const INVALID_IMEI: i16 = -1;
    /// The IMEI is not known to the gateway.
    pub const UNKNOWN_IMEI: i16 = -2;
    /// The payload is larger than the gateway takes for this IMEI.
    pub const PAYLOAD_TOO_LARGE: i16 = -3;
    /// No payload, and no ring alert asked for.
    pub const PAYLOAD_EXPECTED: i16 = -4;
    /// The IMEI's MT queue is full (50 messages).
    pub const QUEUE_FULL: i16 = -5;
    /// MT resources unavailable at the gateway.
    pub const RESOURCES_UNAVAILABLE: i16 = -6;
    /// The message breaks the DirectIP protocol.
    pub const PROTOCOL_ERROR: i16 = -7;

    /// What a status means.
    pub fn meaning(status: i16) -> &'static str {
        match status {
            s if s > 0 => "queued (the status is its place in the MT queue)",
            0 => "no payload: a ring alert only",
            -1 => "invalid IMEI (not 15 digits)",
            -2 => "unknown IMEI",
            -3 => "payload larger than the maximum allowed",
            -4 => "payload expected, none received",
            -5 => "MT message queue full",
            -6 => "MT resources unavailable",
            -7 => "violation of the MT DirectIP protocol",
            -8 => "ring alerts to the IMEI are disabled",
            -9 => "the IMEI is not attached",
            -10 => "source address refused by the MT filter",
            -11 => "MTMSN out of range",
            _ => "refused",
        }
    }
}

/// Why bytes are not a DirectIP message.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DirectIpError {
    /// Fewer bytes than the pre-header and its length say.
    #[error("{got} bytes, the message needs {needed}")]
    Truncated {
        /// Bytes given.
        got: usize,
        /// Bytes needed.
        needed: usize,
    },
    /// A protocol revision other than 1.
    #[error("protocol revision {0}, not 1")]
    Revision(u8),
    /// An IE whose length runs past the message's end.
    #[error("IE {id:#04x} of {length} bytes runs past the message's end")]
    IeOverrun {
        /// Its id.
        id: u8,
        /// Its length.
        length: usize,
    },
    /// An IE of the wrong length, or content that does not parse.
    #[error("IE {id:#04x}: {reason}")]
    BadIe {
        /// Its id.
        id: u8,
        /// What is wrong.
        reason: String,
    },
    /// An IE the message must have is missing.
    #[error("no IE {0:#04x}")]
    Missing(u8),
}

/// One information element.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Ie {
    /// Its id.
    pub id: u8,
    /// Its content.
    pub content: Vec<u8>,
}

/// The bytes of a message made of `ies`.
pub fn encode(ies: &[Ie]) -> Vec<u8> {
    let body: usize = ies.iter().map(|ie| 3 + ie.content.len()).sum();
    let mut out = Vec::with_capacity(PRE_HEADER_BYTES + body);
    out.push(PROTOCOL_REVISION);
    out.extend_from_slice(&(body.min(usize::from(u16::MAX)) as u16).to_be_bytes());
    for ie in ies {
        out.push(ie.id);
        out.extend_from_slice(&(ie.content.len().min(usize::from(u16::MAX)) as u16).to_be_bytes());
        out.extend_from_slice(&ie.content);
    }
    out
}

/// The length of the whole message whose first bytes are `start` (at
/// least the pre-header), for a reader to know how much to read.
pub fn message_length(start: &[u8]) -> Option<usize> {
    let pre = start.get(..PRE_HEADER_BYTES)?;
    Some(PRE_HEADER_BYTES + usize::from(u16::from_be_bytes([pre[1], pre[2]])))
}

/// The IEs of a message (its pre-header checked; bytes after its length
/// are ignored).
pub fn decode(bytes: &[u8]) -> Result<Vec<Ie>, DirectIpError> {
    let needed = message_length(bytes).ok_or(DirectIpError::Truncated {
        got: bytes.len(),
        needed: PRE_HEADER_BYTES,
    })?;
    if bytes[0] != PROTOCOL_REVISION {
        return Err(DirectIpError::Revision(bytes[0]));
    }
    let body = bytes
        .get(PRE_HEADER_BYTES..needed)
        .ok_or(DirectIpError::Truncated {
            got: bytes.len(),
            needed,
        })?;
    let mut ies = Vec::new();
    let mut rest = body;
    while !rest.is_empty() {
        if rest.len() < 3 {
            return Err(DirectIpError::IeOverrun {
                id: rest[0],
                length: 0,
            });
        }
        let id = rest[0];
        let length = usize::from(u16::from_be_bytes([rest[1], rest[2]]));
        let content = rest
            .get(3..3 + length)
            .ok_or(DirectIpError::IeOverrun { id, length })?;
        ies.push(Ie {
            id,
            content: content.to_vec(),
        });
        rest = &rest[3 + length..];
    }
    Ok(ies)
}

/// A field reader over an IE's content.
struct Fields<'a> {
    id: u8,
    bytes: &'a [u8],
}

impl<'a> Fields<'a> {
    fn new(ie: &'a Ie, length: usize) -> Result<Self, DirectIpError> {
        if ie.content.len() != length {
            return Err(DirectIpError::BadIe {
                id: ie.id,
                reason: format!("{} bytes, not {length}", ie.content.len()),
            });
        }
        Ok(Fields {
            id: ie.id,
            bytes: &ie.content,
        })
    }

    fn take(&mut self, n: usize) -> &'a [u8] {
        let (head, tail) = self.bytes.split_at(n.min(self.bytes.len()));
        self.bytes = tail;
        head
    }

    fn u8(&mut self) -> u8 {
        self.take(1).first().copied().unwrap_or(0)
    }

    fn u16(&mut self) -> u16 {
        let b = self.take(2);
        u16::from_be_bytes([
            b.first().copied().unwrap_or(0),
            b.get(1).copied().unwrap_or(0),
        ])
    }

    fn u32(&mut self) -> u32 {
        let b = self.take(4);
        let mut a = [0u8; 4];
        a[..b.len()].copy_from_slice(b);
        u32::from_be_bytes(a)
    }

    fn imei(&mut self) -> Result<String, DirectIpError> {
        let id = self.id;
        let b = self.take(IMEI_BYTES);
        String::from_utf8(b.to_vec()).map_err(|_| DirectIpError::BadIe {
            id,
            reason: "the IMEI is not ASCII".into(),
        })
    }
}

/// Characters of an IMEI.
pub const IMEI_BYTES: usize = 15;

fn imei_bytes(imei: &str) -> [u8; IMEI_BYTES] {
    let mut out = [b'0'; IMEI_BYTES];
    for (o, b) in out.iter_mut().zip(imei.bytes()) {
        *o = b;
    }
    out
}

/// Whether `imei` is 15 decimal digits.
pub fn valid_imei(imei: &str) -> bool {
    imei.len() == IMEI_BYTES && imei.bytes().all(|b| b.is_ascii_digit())
}

/// The MO header (IE 0x01).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MoHeader {
    /// The gateway's call detail record reference.
    pub cdr_reference: u32,
    /// The transceiver's IMEI.
    pub imei: String,
    /// The session's status (0 success; see the Developers Guide).
    pub session_status: u8,
    /// The MO message's sequence number.
    pub momsn: u16,
    /// The MT message sequence number of the session.
    pub mtmsn: u16,
    /// When the session was (Unix seconds, UTC).
    pub time_of_session: u32,
}

/// Where the transceiver was, as the gateway estimates it (IE 0x03).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoLocation {
    /// Degrees north (negative: south).
    pub latitude: f64,
    /// Degrees east (negative: west).
    pub longitude: f64,
    /// Radius (km) around the point holding the transceiver with 80 % likelihood.
    pub cep_radius_km: u32,
}

/// An MO message as the gateway delivers it.
#[derive(Debug, Clone, PartialEq)]
pub struct MoMessage {
    /// Its header.
    pub header: MoHeader,
    /// The message (none for a mailbox check, which DirectIP may also deliver).
    pub payload: Option<Vec<u8>>,
    /// The location estimate, when given.
    pub location: Option<MoLocation>,
}

impl MoLocation {
    fn encode(&self) -> Vec<u8> {
        let mut flags = 0u8;
        if self.latitude < 0.0 {
            flags |= 0x02;
        }
        if self.longitude < 0.0 {
            flags |= 0x01;
        }
        let split = |v: f64| {
            let v = v.abs();
            let deg = v.floor();
            let thousandths = ((v - deg) * 60.0 * 1000.0).round().min(59_999.0);
            (deg as u8, thousandths as u16)
        };
        let (lat_d, lat_m) = split(self.latitude);
        let (lon_d, lon_m) = split(self.longitude);
        let mut out = vec![flags, lat_d];
        out.extend_from_slice(&lat_m.to_be_bytes());
        out.push(lon_d);
        out.extend_from_slice(&lon_m.to_be_bytes());
        out.extend_from_slice(&self.cep_radius_km.to_be_bytes());
        out
    }

    fn decode(ie: &Ie) -> Result<MoLocation, DirectIpError> {
        let mut f = Fields::new(ie, 11)?;
        let flags = f.u8();
        let lat = f64::from(f.u8()) + f64::from(f.u16()) / 60_000.0;
        let lon = f64::from(f.u8()) + f64::from(f.u16()) / 60_000.0;
        let cep = f.u32();
        Ok(MoLocation {
            latitude: if flags & 0x02 != 0 { -lat } else { lat },
            longitude: if flags & 0x01 != 0 { -lon } else { lon },
            cep_radius_km: cep,
        })
    }
}

impl MoMessage {
    /// The message's bytes.
    pub fn encode(&self) -> Vec<u8> {
        let h = &self.header;
        let mut header = Vec::with_capacity(28);
        header.extend_from_slice(&h.cdr_reference.to_be_bytes());
        header.extend_from_slice(&imei_bytes(&h.imei));
        header.push(h.session_status);
        header.extend_from_slice(&h.momsn.to_be_bytes());
        header.extend_from_slice(&h.mtmsn.to_be_bytes());
        header.extend_from_slice(&h.time_of_session.to_be_bytes());
        let mut ies = vec![Ie {
            id: iei::MO_HEADER,
            content: header,
        }];
        if let Some(location) = &self.location {
            ies.push(Ie {
                id: iei::MO_LOCATION,
                content: location.encode(),
            });
        }
        if let Some(payload) = &self.payload {
            ies.push(Ie {
                id: iei::MO_PAYLOAD,
                content: payload.clone(),
            });
        }
        encode(&ies)
    }

    /// The MO message in `bytes` (its header IE required).
    pub fn decode(bytes: &[u8]) -> Result<MoMessage, DirectIpError> {
        let ies = decode(bytes)?;
        let mut header = None;
        let mut payload = None;
        let mut location = None;
        for ie in &ies {
            match ie.id {
                iei::MO_HEADER => {
                    let mut f = Fields::new(ie, 28)?;
                    header = Some(MoHeader {
                        cdr_reference: f.u32(),
                        imei: f.imei()?,
                        session_status: f.u8(),
                        momsn: f.u16(),
                        mtmsn: f.u16(),
                        time_of_session: f.u32(),
                    });
                }
                iei::MO_PAYLOAD => payload = Some(ie.content.clone()),
                iei::MO_LOCATION => location = Some(MoLocation::decode(ie)?),
                _ => {}
            }
        }
        Ok(MoMessage {
            header: header.ok_or(DirectIpError::Missing(iei::MO_HEADER))?,
            payload,
            location,
        })
    }
}

/// An MT message for the gateway.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MtMessage {
    /// The vendor's number for the message (echoed in the confirmation).
    pub client_id: u32,
    /// The transceiver it is for.
    pub imei: String,
    /// Disposition flags ([`disposition`]).
    pub disposition_flags: u16,
    /// The message (none: a ring alert or flush only).
    pub payload: Option<Vec<u8>>,
}

impl MtMessage {
    /// The message's bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut header = Vec::with_capacity(21);
        header.extend_from_slice(&self.client_id.to_be_bytes());
        header.extend_from_slice(&imei_bytes(&self.imei));
        header.extend_from_slice(&self.disposition_flags.to_be_bytes());
        let mut ies = vec![Ie {
            id: iei::MT_HEADER,
            content: header,
        }];
        if let Some(payload) = &self.payload {
            ies.push(Ie {
                id: iei::MT_PAYLOAD,
                content: payload.clone(),
            });
        }
        encode(&ies)
    }

    /// The MT message in `bytes` (its header IE required).
    pub fn decode(bytes: &[u8]) -> Result<MtMessage, DirectIpError> {
        let ies = decode(bytes)?;
        let mut out: Option<MtMessage> = None;
        let mut payload = None;
        for ie in &ies {
            match ie.id {
                iei::MT_HEADER => {
                    let mut f = Fields::new(ie, 21)?;
                    out = Some(MtMessage {
                        client_id: f.u32(),
                        imei: f.imei()?,
                        disposition_flags: f.u16(),
                        payload: None,
                    });
                }
                iei::MT_PAYLOAD => payload = Some(ie.content.clone()),
                _ => {}
            }
        }
        let mut out = out.ok_or(DirectIpError::Missing(iei::MT_HEADER))?;
        out.payload = payload;
        Ok(out)
    }
}

/// The gateway's answer to an MT message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MtConfirmation {
    /// The vendor's number of the message.
    pub client_id: u32,
    /// The transceiver it is for.
    pub imei: String,
    /// The gateway's reference of the message.
    pub auto_id: u32,
    /// Above 0: its place in the MT queue; 0: no payload; below 0: refused ([`mt_status`]).
    pub status: i16,
}

impl MtConfirmation {
    /// The message's bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut c = Vec::with_capacity(25);
        c.extend_from_slice(&self.client_id.to_be_bytes());
        c.extend_from_slice(&imei_bytes(&self.imei));
        c.extend_from_slice(&self.auto_id.to_be_bytes());
        c.extend_from_slice(&self.status.to_be_bytes());
        encode(&[Ie {
            id: iei::MT_CONFIRMATION,
            content: c,
        }])
    }

    /// The confirmation in `bytes`.
    pub fn decode(bytes: &[u8]) -> Result<MtConfirmation, DirectIpError> {
        let ies = decode(bytes)?;
        let ie = ies
            .iter()
            .find(|ie| ie.id == iei::MT_CONFIRMATION)
            .ok_or(DirectIpError::Missing(iei::MT_CONFIRMATION))?;
        let mut f = Fields::new(ie, 25)?;
        Ok(MtConfirmation {
            client_id: f.u32(),
            imei: f.imei()?,
            auto_id: f.u32(),
            status: f.u16() as i16,
        })
    }

    /// Whether the gateway took the message.
    pub fn accepted(&self) -> bool {
        self.status >= 0
    }
}

impl fmt::Display for MtConfirmation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "MT confirmation for {} (client id {}): status {} ({})",
            self.imei,
            self.client_id,
            self.status,
            mt_status::meaning(self.status)
        )
    }
}

/// Largest DirectIP message read (pre-header included): the length field
/// allows no more.
pub const MAX_MESSAGE: usize = PRE_HEADER_BYTES + u16::MAX as usize;

/// Reads one whole DirectIP message from `reader` (pre-header, then as
/// many bytes as it says).
pub async fn read_message<R: tokio::io::AsyncRead + Unpin>(
    reader: &mut R,
) -> std::io::Result<Vec<u8>> {
    use tokio::io::AsyncReadExt;
    let mut pre = [0u8; PRE_HEADER_BYTES];
    reader.read_exact(&mut pre).await?;
    let length = message_length(&pre).unwrap_or(PRE_HEADER_BYTES);
    let mut out = pre.to_vec();
    out.resize(length, 0);
    reader.read_exact(&mut out[PRE_HEADER_BYTES..]).await?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn mo() -> MoMessage {
        MoMessage {
            header: MoHeader {
                cdr_reference: 0x0102_0304,
                imei: "300234010753370".into(),
                session_status: 0,
                momsn: 7,
                mtmsn: 0,
                time_of_session: 1_700_000_000,
            },
            payload: Some(b"hello".to_vec()),
            location: Some(MoLocation {
                latitude: 41.5,
                longitude: -70.675,
                cep_radius_km: 3,
            }),
        }
    }

    #[test]
    fn an_mo_message_as_the_guide_lays_it_out() {
        let bytes = mo().encode();
        // Pre-header: revision 1, 31 + 14 + 8 bytes follow.
        assert_eq!(&bytes[..3], &[1, 0, 53]);
        // The header IE: id 1, 28 bytes, CDR, IMEI, status, MOMSN, MTMSN, time.
        assert_eq!(&bytes[3..6], &[0x01, 0, 28]);
        assert_eq!(&bytes[6..10], &[1, 2, 3, 4]);
        assert_eq!(&bytes[10..25], b"300234010753370");
        assert_eq!(bytes[25], 0);
        assert_eq!(&bytes[26..28], &[0, 7]);
        assert_eq!(&bytes[30..34], &1_700_000_000u32.to_be_bytes());
        // Location, then payload.
        assert_eq!(&bytes[34..37], &[0x03, 0, 11]);
        assert_eq!(bytes[37], 0x01, "west");
        assert_eq!(bytes[38], 41);
        assert_eq!(&bytes[39..41], &30_000u16.to_be_bytes());
        assert_eq!(&bytes[48..51], &[0x02, 0, 5]);
        assert_eq!(&bytes[51..], b"hello");
        let back = MoMessage::decode(&bytes).unwrap();
        assert_eq!(back.header, mo().header);
        assert_eq!(back.payload, mo().payload);
        let loc = back.location.unwrap();
        assert!((loc.latitude - 41.5).abs() < 1e-4 && (loc.longitude + 70.675).abs() < 1e-4);
    }

    #[test]
    fn mt_message_and_confirmation() {
        let mt = MtMessage {
            client_id: 9,
            imei: "300234010753370".into(),
            disposition_flags: disposition::FLUSH_MT_QUEUE,
            payload: Some(vec![0, 1, 2]),
        };
        let bytes = mt.encode();
        assert_eq!(&bytes[..3], &[1, 0, 24 + 6]);
        assert_eq!(&bytes[3..6], &[0x41, 0, 21]);
        assert_eq!(&bytes[6..10], &[0, 0, 0, 9]);
        assert_eq!(&bytes[25..27], &[0, 1]);
        assert_eq!(&bytes[27..30], &[0x42, 0, 3]);
        assert_eq!(MtMessage::decode(&bytes).unwrap(), mt);
        let c = MtConfirmation {
            client_id: 9,
            imei: mt.imei.clone(),
            auto_id: 77,
            status: mt_status::UNKNOWN_IMEI,
        };
        let bytes = c.encode();
        assert_eq!(&bytes[..6], &[1, 0, 28, 0x44, 0, 25]);
        assert_eq!(&bytes[bytes.len() - 2..], &[0xff, 0xfe]);
        let back = MtConfirmation::decode(&bytes).unwrap();
        assert_eq!(back, c);
        assert!(!back.accepted());
        assert!(back.to_string().contains("unknown IMEI"));
    }

    #[test]
    fn broken_messages_are_errors() {
        let bytes = mo().encode();
        assert!(matches!(
            decode(&bytes[..10]),
            Err(DirectIpError::Truncated { .. })
        ));
        let mut wrong = bytes.clone();
        wrong[0] = 2;
        assert_eq!(decode(&wrong), Err(DirectIpError::Revision(2)));
        // An IE claiming more than there is.
        let mut over = bytes.clone();
        over[5] = 200;
        assert!(matches!(
            decode(&over),
            Err(DirectIpError::IeOverrun { id: 1, .. })
        ));
        let no_header = encode(&[Ie {
            id: iei::MO_PAYLOAD,
            content: b"x".to_vec(),
        }]);
        assert_eq!(
            MoMessage::decode(&no_header),
            Err(DirectIpError::Missing(1))
        );
        let short = encode(&[Ie {
            id: iei::MT_HEADER,
            content: vec![0; 20],
        }]);
        assert!(matches!(
            MtMessage::decode(&short),
            Err(DirectIpError::BadIe { id: 0x41, .. })
        ));
        assert!(valid_imei("300234010753370") && !valid_imei("30023401075337x"));
    }

    #[tokio::test]
    async fn messages_are_read_whole_from_a_stream() {
        let (mut a, mut b) = tokio::io::duplex(256);
        let bytes = mo().encode();
        tokio::io::AsyncWriteExt::write_all(&mut a, &bytes)
            .await
            .unwrap();
        assert_eq!(read_message(&mut b).await.unwrap(), bytes);
    }

    proptest! {
        #[test]
        fn garbage_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..120)) {
            let _ = decode(&bytes);
            let _ = MoMessage::decode(&bytes);
            let _ = MtMessage::decode(&bytes);
            let _ = MtConfirmation::decode(&bytes);
        }

        #[test]
        fn ies_round_trip(ies in proptest::collection::vec(
            (any::<u8>(), proptest::collection::vec(any::<u8>(), 0..40)), 0..6)
        ) {
            let ies: Vec<Ie> = ies.into_iter().map(|(id, content)| Ie { id, content }).collect();
            prop_assert_eq!(decode(&encode(&ies)).unwrap(), ies);
        }
    }
}
