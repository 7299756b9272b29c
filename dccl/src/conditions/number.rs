//! Lua 5.3 numbers: reading numerals (in scripts and in strings converted
//! to numbers), writing them as `tostring` does (`%.14g`, integers as
//! such), and comparing integers with floats exactly.

use super::lexer::Tok;

/// A numeral as the lexer reads it: an integer when it has no dot nor
/// exponent and fits (hexadecimal integers wrap around), else a float.
pub(crate) fn parse_numeral(text: &str) -> Option<Tok> {
    if let Some(i) = str_to_int(text) {
        return Some(Tok::Int(i));
    }
    str_to_float(text).map(Tok::Num)
}

/// A string converted to a number as Lua's arithmetic does: blanks around
/// it allowed, an optional sign; `None` when it is not a numeral.
pub(crate) fn string_to_number(s: &[u8]) -> Option<super::eval::Val<'static>> {
    use super::eval::Val;
    let s = std::str::from_utf8(s).ok()?;
    let t = s.trim_matches(|c: char| c.is_ascii_whitespace());
    if t.is_empty() {
        return None;
    }
    let (neg, body) = match t.as_bytes()[0] {
        b'-' => (true, &t[1..]),
        b'+' => (false, &t[1..]),
        _ => (false, t),
    };
    if let Some(i) = str_to_int(body) {
        return Some(Val::Int(if neg { i.wrapping_neg() } else { i }));
    }
    str_to_float(body).map(|f| Val::Num(if neg { -f } else { f }))
}

/// An unsigned integer numeral: decimal (`None` on overflow: then it is a
/// float) or hexadecimal (wrapping).
fn str_to_int(t: &str) -> Option<i64> {
    let b = t.as_bytes();
    if b.len() > 2 && (t.starts_with("0x") || t.starts_with("0X")) {
        let digits = &t[2..];
        if !digits.bytes().all(|c| c.is_ascii_hexdigit()) {
            return None;
        }
        let mut v: u64 = 0;
        for c in digits.bytes() {
            v = v
                .wrapping_mul(16)
                .wrapping_add((c as char).to_digit(16)? as u64);
        }
        return Some(v as i64);
    }
    if b.is_empty() || !b.iter().all(u8::is_ascii_digit) {
        return None;
    }
    let mut v: i64 = 0;
    for c in b {
        v = v.checked_mul(10)?.checked_add(i64::from(c - b'0'))?;
    }
    Some(v)
}

/// An unsigned float numeral (decimal or hexadecimal with a binary
/// exponent); Lua refuses `inf` and `nan` spelled out.
fn str_to_float(t: &str) -> Option<f64> {
    if t.contains(['n', 'N']) || t.is_empty() {
        return None;
    }
    if t.starts_with("0x") || t.starts_with("0X") {
        return hex_float(&t[2..]);
    }
    if !t
        .bytes()
        .all(|c| c.is_ascii_digit() || matches!(c, b'.' | b'e' | b'E' | b'+' | b'-'))
        || t.starts_with(['+', '-'])
    {
        return None;
    }
    t.parse::<f64>().ok()
}

fn hex_float(t: &str) -> Option<f64> {
    let (mantissa, exp) = match t.find(['p', 'P']) {
        Some(p) => (&t[..p], Some(&t[p + 1..])),
        None => (t, None),
    };
    let (int, frac) = mantissa.split_once('.').unwrap_or((mantissa, ""));
    if int.is_empty() && frac.is_empty() {
        return None;
    }
    let mut v = 0.0f64;
    for c in int.chars() {
        v = v * 16.0 + f64::from(c.to_digit(16)?);
    }
    let mut scale = 1.0 / 16.0;
    for c in frac.chars() {
        v += f64::from(c.to_digit(16)?) * scale;
        scale /= 16.0;
    }
    let e: i32 = match exp {
        Some(e) => e.parse().ok()?,
        None => 0,
    };
    Some(v * 2f64.powi(e))
}

/// A float as Lua's `tostring` writes it: C's `%.14g`, then `.0` when the
/// result looks like an integer.
pub(crate) fn float_to_string(f: f64) -> String {
    if f.is_nan() {
        return if f.is_sign_negative() { "-nan" } else { "nan" }.to_string();
    }
    if f.is_infinite() {
        return if f < 0.0 { "-inf" } else { "inf" }.to_string();
    }
    let mut s = format_g14(f);
    if s.bytes().all(|c| c == b'-' || c.is_ascii_digit()) {
        s.push_str(".0");
    }
    s
}

/// C's `%.14g` of a finite double.
fn format_g14(f: f64) -> String {
    const P: i32 = 14;
    if f == 0.0 {
        return if f.is_sign_negative() { "-0" } else { "0" }.to_string();
    }
    // The exponent after rounding to P significant digits.
    let sci = format!("{:.*e}", (P - 1) as usize, f);
    let (mant, exp) = sci.split_once('e').unwrap_or((&sci, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    if !(-4..P).contains(&exp) {
        let mant = strip_zeros(mant);
        let sign = if exp < 0 { '-' } else { '+' };
        format!("{mant}e{sign}{:02}", exp.abs())
    } else {
        let decimals = (P - 1 - exp).max(0) as usize;
        strip_zeros(&format!("{f:.decimals$}")).to_string()
    }
}

fn strip_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

/// 2^63, the first float beyond the integers.
const TWO_63: f64 = 9_223_372_036_854_775_808.0;

/// `i < f` exactly.
pub(crate) fn int_lt_float(i: i64, f: f64) -> bool {
    if f.is_nan() {
        false
    } else if f >= TWO_63 {
        true
    } else if f > -TWO_63 {
        i < f.ceil() as i64
    } else {
        false
    }
}

/// `i <= f` exactly.
pub(crate) fn int_le_float(i: i64, f: f64) -> bool {
    if f.is_nan() {
        false
    } else if f >= TWO_63 {
        true
    } else if f >= -TWO_63 {
        i <= f.floor() as i64
    } else {
        false
    }
}

/// `f < i` exactly.
pub(crate) fn float_lt_int(f: f64, i: i64) -> bool {
    if f.is_nan() || f >= TWO_63 {
        false
    } else if f >= -TWO_63 {
        (f.floor() as i64) < i
    } else {
        true
    }
}

/// `f <= i` exactly.
pub(crate) fn float_le_int(f: f64, i: i64) -> bool {
    if f.is_nan() || f >= TWO_63 {
        false
    } else if f > -TWO_63 {
        (f.ceil() as i64) <= i
    } else {
        true
    }
}

/// The integer a float equals exactly, if any (Lua's float-to-integer
/// conversion for table keys, bitwise operators and integer arguments).
pub(crate) fn float_to_int(f: f64) -> Option<i64> {
    (f.floor() == f && (-TWO_63..TWO_63).contains(&f)).then_some(f as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_print_as_lua_prints_them() {
        for (f, s) in [
            (1.0, "1.0"),
            (0.1, "0.1"),
            (1.0 / 3.0, "0.33333333333333"),
            (1e15, "1e+15"),
            (1e14, "1e+14"),
            (123456789012345.0, "1.2345678901234e+14"),
            (1e-5, "1e-05"),
            (0.0001, "0.0001"),
            (-2.5, "-2.5"),
            (f64::INFINITY, "inf"),
            (-0.0, "-0.0"),
            (150.7, "150.7"),
        ] {
            assert_eq!(float_to_string(f), s, "{f}");
        }
    }

    #[test]
    fn numerals_read_as_lua_reads_them() {
        assert_eq!(parse_numeral("10"), Some(Tok::Int(10)));
        assert_eq!(parse_numeral("0x10"), Some(Tok::Int(16)));
        assert_eq!(parse_numeral("0xffffffffffffffff"), Some(Tok::Int(-1)));
        assert_eq!(parse_numeral("9223372036854775808"), Some(Tok::Num(TWO_63)));
        assert_eq!(parse_numeral("3."), Some(Tok::Num(3.0)));
        assert_eq!(parse_numeral(".5"), Some(Tok::Num(0.5)));
        assert_eq!(parse_numeral("0x1p4"), Some(Tok::Num(16.0)));
        assert_eq!(parse_numeral("1e2"), Some(Tok::Num(100.0)));
        assert_eq!(parse_numeral("1e"), None);
        assert!(string_to_number(b" 0x10 ").is_some());
        assert!(string_to_number(b"inf").is_none());
        assert!(string_to_number(b"1 2").is_none());
    }

    #[test]
    fn integers_and_floats_compare_exactly() {
        assert!(int_lt_float(1, 1.5));
        assert!(!int_lt_float(2, 1.5));
        assert!(int_le_float(i64::MAX, 9.3e18));
        assert!(float_lt_int(-1e300, i64::MIN));
        assert!(float_le_int(2.0, 2));
        assert!(!float_lt_int(f64::NAN, 0));
        assert_eq!(float_to_int(3.0), Some(3));
        assert_eq!(float_to_int(3.5), None);
    }
}
