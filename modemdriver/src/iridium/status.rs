//! The status codes of an SBD session (`+SBDIX`), with their meanings
//! (Iridium ISU AT Command Reference, `+SBDIX` and `+SBDIXA`).

/// The mobile-originated status of a session: whether the MO buffer (if
/// it held a message) reached the gateway.
///
/// 0–4 are success; 5–36 failure. Codes without a meaning of their own are
/// "reserved", success or failure by their range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct MoStatus(pub u8);

impl MoStatus {
    /// The MO message, if any, was transferred.
    pub const SUCCESS: MoStatus = MoStatus(0);
    /// Transferred; the MT message queued was too big to be transferred.
    pub const MT_TOO_BIG: MoStatus = MoStatus(1);
    /// The gateway reported that the call did not complete in the allowed time.
    pub const GSS_TIMEOUT: MoStatus = MoStatus(10);
    /// The MO message queue at the gateway is full.
    pub const GSS_QUEUE_FULL: MoStatus = MoStatus(11);
    /// The gateway reported that the session did not complete.
    pub const GSS_INCOMPLETE: MoStatus = MoStatus(13);
    /// Invalid segment size.
    pub const BAD_SEGMENT_SIZE: MoStatus = MoStatus(14);
    /// Access is denied.
    pub const ACCESS_DENIED: MoStatus = MoStatus(15);
    /// Gateway not responding (local session timeout).
    pub const GATEWAY_NOT_RESPONDING: MoStatus = MoStatus(17);
    /// Connection lost (RF drop).
    pub const RF_DROP: MoStatus = MoStatus(18);
    /// Link failure (a protocol error ended the call).
    pub const LINK_FAILURE: MoStatus = MoStatus(19);
    /// No network service: the session could not start.
    pub const NO_SERVICE: MoStatus = MoStatus(32);
    /// Antenna fault: the session could not start.
    pub const ANTENNA_FAULT: MoStatus = MoStatus(33);
    /// Radio disabled (`*R0`): the session could not start.
    pub const RADIO_DISABLED: MoStatus = MoStatus(34);
    /// The transceiver is busy: the session could not start.
    pub const BUSY: MoStatus = MoStatus(35);
    /// Try later: the required time between attempts has not passed.
    pub const TRY_LATER: MoStatus = MoStatus(36);

    /// Whether the session succeeded (0–4).
    pub fn success(self) -> bool {
        self.0 <= 4
    }

    /// What the code means.
    pub fn meaning(self) -> &'static str {
        match self.0 {
            0 => "MO message, if any, transferred successfully",
            1 => "MO message, if any, transferred successfully, but the MT message in the queue was too big to be transferred",
            2 => "MO message, if any, transferred successfully, but the requested location update was not accepted",
            3 | 4 => "reserved, but indicating MO session success",
            10 => "the gateway reported that the call did not complete in the allowed time",
            11 => "the MO message queue at the gateway is full",
            12 => "the MO message has too many segments",
            13 => "the gateway reported that the session did not complete",
            14 => "invalid segment size",
            15 => "access is denied",
            16 => "the transceiver has been locked and may not make SBD calls",
            17 => "gateway not responding (local session timeout)",
            18 => "connection lost (RF drop)",
            19 => "link failure (a protocol error caused termination of the call)",
            32 => "no network service, unable to initiate call",
            33 => "antenna fault, unable to initiate call",
            34 => "radio is disabled, unable to initiate call",
            35 => "the transceiver is busy, unable to initiate call",
            36 => "try later, must wait before the next session attempt",
            _ => "reserved, but indicating MO session failure",
        }
    }

    /// Whether trying again soon may help: not for a transceiver locked
    /// (16), access denied (15) or a bad size (12, 14), which fail the same
    /// way every time.
    pub fn worth_retrying(self) -> bool {
        !matches!(self.0, 12 | 14 | 15 | 16)
    }
}

impl std::fmt::Display for MoStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "MO status {}: {}", self.0, self.meaning())
    }
}

/// The mobile-terminated status of a session.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MtStatus {
    /// No MT message to receive (0).
    NoMessage,
    /// An MT message was received into the MT buffer (1).
    Received,
    /// An error checking the mailbox or receiving the message (2).
    Error,
}

impl MtStatus {
    /// The status of code `code` (0, 1 or 2).
    pub fn from_code(code: u8) -> Option<MtStatus> {
        match code {
            0 => Some(MtStatus::NoMessage),
            1 => Some(MtStatus::Received),
            2 => Some(MtStatus::Error),
            _ => None,
        }
    }

    /// The code of the status.
    pub fn code(self) -> u8 {
        match self {
            MtStatus::NoMessage => 0,
            MtStatus::Received => 1,
            MtStatus::Error => 2,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn success_is_zero_to_four() {
        for code in 0..=4 {
            assert!(MoStatus(code).success());
        }
        for code in [5, 13, 18, 32, 36, 99] {
            assert!(!MoStatus(code).success());
        }
        assert_eq!(
            MoStatus::NO_SERVICE.to_string(),
            "MO status 32: no network service, unable to initiate call"
        );
        assert!(MoStatus(7).meaning().contains("failure"));
        assert!(!MoStatus::ACCESS_DENIED.worth_retrying());
        assert!(MoStatus::RF_DROP.worth_retrying());
        assert_eq!(MtStatus::from_code(1), Some(MtStatus::Received));
        assert_eq!(MtStatus::from_code(3), None);
    }
}
