//! `goby log pcap`: the modem traffic of a mission log as a pcap capture,
//! for Wireshark and tshark with the dissector `goby dccl wireshark`
//! writes.
//!
//! Each raw record that holds a `goby.acomms.protobuf.ModemTransmission`
//! (the UDP driver's datagrams, the acoustic simulator's transmissions)
//! becomes one IPv4/UDP packet, at the record's time, from `10.0.X.Y` (the
//! transmission's source modem id `256·X + Y`) to that of its destination
//! (`10.255.255.255` for a broadcast), both ports the port given
//! (`--udp-port`), so that the dissector made with that `--udp-port`
//! decodes its DCCL frames. Text records (NMEA sentences of serial modems)
//! and records that are not a transmission are left out and counted.
//!
//! The file is a classic pcap (microsecond times, little-endian) of link
//! type `LINKTYPE_RAW` (101: each packet an IP packet, no link header).

use std::io::Write;

use prost::Message;
use protos::goby::acomms::protobuf::ModemTransmission;

use super::read::Record;

/// Link type of the capture: raw IP packets.
pub const LINKTYPE_RAW: u32 = 101;
/// Largest packet kept whole.
const SNAPLEN: u32 = 65_535;

/// What the export wrote and left out.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Exported {
    /// Packets written.
    pub packets: usize,
    /// Raw records left out: text (NMEA), or not a transmission.
    pub skipped: usize,
}

/// Writes the raw records of `records` that hold a transmission to `out`
/// as a pcap capture (header included).
pub fn write_pcap(
    records: &[Record],
    udp_port: u16,
    out: &mut dyn Write,
) -> std::io::Result<Exported> {
    let mut header = Vec::with_capacity(24);
    header.extend_from_slice(&0xa1b2_c3d4u32.to_le_bytes());
    header.extend_from_slice(&2u16.to_le_bytes());
    header.extend_from_slice(&4u16.to_le_bytes());
    header.extend_from_slice(&0i32.to_le_bytes());
    header.extend_from_slice(&0u32.to_le_bytes());
    header.extend_from_slice(&SNAPLEN.to_le_bytes());
    header.extend_from_slice(&LINKTYPE_RAW.to_le_bytes());
    out.write_all(&header)?;
    let mut exported = Exported::default();
    for record in records.iter().filter(|r| r.kind == "raw") {
        let Some(payload) = transmission_bytes(record) else {
            exported.skipped += 1;
            continue;
        };
        let Ok(transmission) = ModemTransmission::decode(payload.as_slice()) else {
            exported.skipped += 1;
            continue;
        };
        let packet = udp_packet(
            address(transmission.src()),
            address(transmission.dest()),
            udp_port,
            &payload,
        );
        let t = record.t.unwrap_or(0).max(0);
        let mut head = Vec::with_capacity(16);
        head.extend_from_slice(&((t / 1_000_000) as u32).to_le_bytes());
        head.extend_from_slice(&((t % 1_000_000) as u32).to_le_bytes());
        let len = packet.len() as u32;
        head.extend_from_slice(&len.min(SNAPLEN).to_le_bytes());
        head.extend_from_slice(&len.to_le_bytes());
        out.write_all(&head)?;
        out.write_all(&packet[..packet.len().min(SNAPLEN as usize)])?;
        exported.packets += 1;
    }
    Ok(exported)
}

/// The bytes of a raw record that is not text.
fn transmission_bytes(record: &Record) -> Option<Vec<u8>> {
    if record.fields.contains_key("text") {
        return None;
    }
    hex::decode(record.fields.get("bytes_hex")?.as_str()?).ok()
}

/// The address standing for modem id `id`: `10.0.X.Y` with `id = 256·X + Y`
/// for ids 1 to 65535, else the broadcast `10.255.255.255`.
fn address(id: i32) -> [u8; 4] {
    match u16::try_from(id) {
        Ok(id) if id > 0 => {
            let [x, y] = id.to_be_bytes();
            [10, 0, x, y]
        }
        _ => [10, 255, 255, 255],
    }
}

/// An IPv4 packet holding a UDP datagram of `payload` (IP header checksum
/// set; UDP checksum 0, "none", as IPv4 allows).
fn udp_packet(src: [u8; 4], dst: [u8; 4], port: u16, payload: &[u8]) -> Vec<u8> {
    let udp_len = 8 + payload.len();
    let total = (20 + udp_len).min(usize::from(u16::MAX)) as u16;
    let mut ip = vec![0x45, 0];
    ip.extend_from_slice(&total.to_be_bytes());
    ip.extend_from_slice(&[0, 0, 0x40, 0, 64, 17, 0, 0]);
    ip.extend_from_slice(&src);
    ip.extend_from_slice(&dst);
    let sum = checksum(&ip);
    ip[10..12].copy_from_slice(&sum.to_be_bytes());
    ip.extend_from_slice(&port.to_be_bytes());
    ip.extend_from_slice(&port.to_be_bytes());
    ip.extend_from_slice(&(udp_len.min(usize::from(u16::MAX)) as u16).to_be_bytes());
    ip.extend_from_slice(&[0, 0]);
    ip.extend_from_slice(payload);
    ip
}

/// The Internet checksum (RFC 1071) of `bytes`.
fn checksum(bytes: &[u8]) -> u16 {
    let mut sum: u32 = bytes
        .chunks(2)
        .map(|c| u32::from(u16::from_be_bytes([c[0], *c.get(1).unwrap_or(&0)])))
        .sum();
    while sum > 0xffff {
        sum = (sum & 0xffff) + (sum >> 16);
    }
    !(sum as u16)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ip_header_checksum_checks_out() {
        let packet = udp_packet([10, 0, 0, 1], [10, 0, 0, 2], 50000, b"abc");
        assert_eq!(checksum(&packet[..20]), 0);
        assert_eq!(packet.len(), 20 + 8 + 3);
        assert_eq!(&packet[20..22], &50000u16.to_be_bytes());
        assert_eq!(address(258), [10, 0, 1, 2]);
        assert_eq!(address(0), [10, 255, 255, 255]);
    }
}
