//! The rounding and sizing arithmetic of the reference implementation,
//! reproduced operation for operation (including its single-precision steps
//! for `float` fields) so that encodings agree bit for bit.

/// `ceil(log2(v))`, with 0 for 0 and 1.
pub fn ceil_log2_u64(v: u64) -> u32 {
    if v <= 1 {
        return 0;
    }
    let floor = 63 - v.leading_zeros();
    if v.is_power_of_two() {
        floor
    } else {
        floor + 1
    }
}

/// `ceil(log2(ceil(d)))` as the reference computes it for a double.
pub fn ceil_log2_f64(d: f64) -> u32 {
    ceil_log2_u64(d.ceil() as u64)
}

/// Round half up: `floor(d + 0.5)`.
#[inline]
pub fn round_half_up(d: f64) -> f64 {
    floor(d + 0.5)
}

/// `floor`, computed inline for the common range (the library call is not
/// inlined on baseline x86-64); identical results, signed zeros included.
#[inline]
fn floor(t: f64) -> f64 {
    const EXACT: f64 = 4_503_599_627_370_496.0; // 2^52: every double beyond is an integer
    if t.abs() < EXACT && t != 0.0 {
        let i = t as i64 as f64;
        let f = if i > t { i - 1.0 } else { i };
        if f == 0.0 && t.is_sign_negative() {
            -0.0
        } else {
            f
        }
    } else {
        t.floor()
    }
}

/// `10^p` as the C library's `pow` gives it.
pub fn pow10(p: f64) -> f64 {
    10f64.powf(p)
}

/// Quantizes a double to the nearest multiple of `interval`.
pub fn quantize_f64(value: f64, interval: f64) -> f64 {
    if interval >= 1.0 {
        round_half_up(value / interval) * interval
    } else {
        let inv = 1.0 / interval;
        round_half_up(value * inv) / inv
    }
}

/// Quantizes a float: the arithmetic is done in double, the result narrowed.
pub fn quantize_f32(value: f32, interval: f64) -> f32 {
    quantize_f64(value as f64, interval) as f32
}

/// Rounds a double to `precision` decimal places.
pub fn round_f64(value: f64, precision: i32) -> f64 {
    let scaling = pow10(precision as f64);
    round_half_up(value * scaling) / scaling
}

/// Integer arithmetic used by the numeric codec, for each integer wire type.
pub trait IntWire: Copy + PartialOrd {
    /// Converts to double.
    fn to_f64(self) -> f64;
    /// Converts from double, truncating toward zero (saturating).
    fn from_f64(d: f64) -> Self;
    /// Converts from an unsigned 64-bit value, wrapping.
    fn from_u64(u: u64) -> Self;
    /// Converts to an unsigned 64-bit value, wrapping.
    fn to_u64(self) -> u64;
    /// Wrapping subtraction.
    fn sub(self, o: Self) -> Self;
    /// Wrapping addition.
    fn add(self, o: Self) -> Self;
    /// Remainder (`None` for a zero divisor).
    fn rem(self, o: Self) -> Option<Self>;
}

macro_rules! int_wire {
    ($($t:ty),*) => {$(
        impl IntWire for $t {
            fn to_f64(self) -> f64 { self as f64 }
            fn from_f64(d: f64) -> Self { d as $t }
            fn from_u64(u: u64) -> Self { u as $t }
            fn to_u64(self) -> u64 { self as u64 }
            fn sub(self, o: Self) -> Self { self.wrapping_sub(o) }
            fn add(self, o: Self) -> Self { self.wrapping_add(o) }
            fn rem(self, o: Self) -> Option<Self> { self.checked_rem(o) }
        }
    )*};
}
int_wire!(i32, i64, u32, u64);

/// Quantizes an integer to a multiple of `interval` (fractional intervals
/// leave it unchanged; negative values round toward zero, as the reference does).
pub fn quantize_int<I: IntWire>(value: I, interval: f64) -> I {
    if interval - (interval as u64) as f64 >= f64::EPSILON {
        return value;
    }
    let step = I::from_f64(interval);
    let Some(remainder) = value.rem(step) else {
        return value;
    };
    let mut v = value.sub(remainder);
    if remainder.to_f64() >= interval / 2.0 {
        v = I::from_f64(v.to_f64() + interval);
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ceil_log2_matches_reference() {
        assert_eq!(ceil_log2_u64(0), 0);
        assert_eq!(ceil_log2_u64(1), 0);
        assert_eq!(ceil_log2_u64(2), 1);
        assert_eq!(ceil_log2_u64(3), 2);
        assert_eq!(ceil_log2_u64(4), 2);
        assert_eq!(ceil_log2_u64(6002), 13);
        assert_eq!(ceil_log2_f64(4294967297.0), 33);
    }

    #[test]
    fn inline_floor_matches_the_library() {
        for t in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.5,
            -2.5,
            1e-300,
            -1e-300,
            4.5e15,
            -4.5e15,
            1e300,
            -1e300,
            123456.789,
            -123456.789,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ] {
            let (a, b) = (floor(t), t.floor());
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{t}: {a} vs {b}"
            );
        }
    }

    #[test]
    fn quantize_rounds_half_up() {
        assert_eq!(quantize_f64(196.35, 0.1), 196.4);
        assert_eq!(quantize_f64(-1001.58, 10.0), -1000.0);
        assert_eq!(quantize_int(17i32, 5.0), 15);
        assert_eq!(quantize_int(18i32, 5.0), 20);
        assert_eq!(quantize_int(-18i32, 5.0), -15);
        assert_eq!(quantize_int(7i32, 0.5), 7);
    }
}
