//! Goby3's base conversion of byte strings (`base_convert`): how its
//! drivers write binary packets on lines that reserve a byte (the carriage
//! return), the Benthos ATM-900's frames in base 255 and Iridium RUDICS
//! packets in a reduced base.

/// Writes the little-endian digits of `source` (base `from`) in base `to`,
/// keeping its most significant zero digits (Goby3's `base_convert`).
pub fn base_convert(source: &[u8], from: u32, to: u32) -> Vec<u8> {
    // The number, as little-endian base-2^32 limbs.
    let mut number: Vec<u32> = Vec::new();
    for &digit in source.iter().rev() {
        // number = number * from + digit
        let mut carry = u64::from(digit);
        for limb in number.iter_mut() {
            let v = u64::from(*limb) * u64::from(from) + carry;
            *limb = v as u32;
            carry = v >> 32;
        }
        if carry > 0 {
            number.push(carry as u32);
        }
    }
    let zeros = source.iter().rev().take_while(|&&b| b == 0).count();
    let mut out = Vec::new();
    while number.iter().any(|&l| l != 0) {
        // number, remainder = divmod(number, to)
        let mut remainder = 0u64;
        for limb in number.iter_mut().rev() {
            let v = (remainder << 32) | u64::from(*limb);
            *limb = (v / u64::from(to)) as u32;
            remainder = v % u64::from(to);
        }
        while number.last() == Some(&0) {
            number.pop();
        }
        out.push(remainder as u8);
    }
    out.extend(std::iter::repeat_n(0u8, zeros));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn digits_are_little_endian_and_keep_high_zeros() {
        // 256 = 1*252 + 4.
        assert_eq!(base_convert(&[0, 1], 256, 252), vec![4, 1]);
        assert_eq!(base_convert(&[4, 1], 252, 256), vec![0, 1]);
        // Zero bytes at the most significant end are kept by count.
        assert_eq!(base_convert(&[5, 0, 0], 256, 252), vec![5, 0, 0]);
        assert_eq!(base_convert(&[0, 0], 256, 252), vec![0, 0]);
        assert_eq!(base_convert(&[], 256, 252), Vec::<u8>::new());
        // 0xffff = 65535 = 1*252^2 + 8*252 + 15.
        assert_eq!(base_convert(&[0xff, 0xff], 256, 252), vec![15, 8, 1]);
    }
}
