//! Modem addresses of one byte, as the EvoLogics S2C, the Popoto and the
//! Benthos ATM-900 number their modems: modem id N is address N (1-254),
//! and the broadcast (modem id 0) is address 255.

/// The broadcast address.
pub const BROADCAST: u8 = 255;

/// The address of modem id `id` (0: broadcast); `None` beyond 254.
pub fn address_of(id: i32) -> Option<u8> {
    match id {
        0 => Some(BROADCAST),
        1..=254 => Some(id as u8),
        _ => None,
    }
}

/// The modem id of address `a` (255: broadcast, 0).
pub fn id_of(a: u8) -> i32 {
    if a == BROADCAST {
        0
    } else {
        i32::from(a)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn broadcast_is_255_and_ids_are_themselves() {
        assert_eq!(address_of(0), Some(BROADCAST));
        assert_eq!(address_of(254), Some(254));
        assert_eq!(address_of(255), None);
        assert_eq!(address_of(-1), None);
        assert_eq!(id_of(BROADCAST), 0);
        assert_eq!(id_of(7), 7);
    }
}
