//! Encoded messages written as a protobuf text-format byte string
//! (`"\004\006"`), the `textformat` form of the reference `dccl` tool: bytes
//! C-escaped as the C++ protobuf library prints a `bytes` field.

/// The quoted, C-escaped form of `bytes`: printable ASCII as is, `\n`, `\r`,
/// `\t`, `\"`, `\'`, `\\`, every other byte as three octal digits.
pub(crate) fn escape(bytes: &[u8]) -> String {
    let mut out = String::with_capacity(bytes.len() * 4 + 2);
    out.push('"');
    for &b in bytes {
        match b {
            b'\n' => out.push_str("\\n"),
            b'\r' => out.push_str("\\r"),
            b'\t' => out.push_str("\\t"),
            b'"' => out.push_str("\\\""),
            b'\'' => out.push_str("\\'"),
            b'\\' => out.push_str("\\\\"),
            0x20..=0x7e => out.push(b as char),
            _ => out.push_str(&format!("\\{b:03o}")),
        }
    }
    out.push('"');
    out
}

/// The bytes of a text-format byte string, with or without its surrounding
/// double quotes. Understands the C escapes the protobuf text format does:
/// `\n \r \t \a \b \f \v \\ \' \" \?`, octal (`\0`–`\377`, 1 to 3 digits)
/// and hexadecimal (`\x0`–`\xff`, 1 or 2 digits). Errors give the character
/// position (from 0) in `text`.
pub(crate) fn unescape(text: &str) -> Result<Vec<u8>, String> {
    let (body, start) = match text.strip_prefix('"') {
        Some(rest) => match rest.strip_suffix('"') {
            Some(inner) if inner.bytes().rev().take_while(|&b| b == b'\\').count() % 2 == 0 => {
                (inner, 1)
            }
            _ => return Err("opening '\"' without a closing one".to_string()),
        },
        None => (text, 0),
    };
    let bytes = body.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let b = bytes[i];
        if b == b'"' {
            return Err(format!("unescaped '\"' at character {}", start + i));
        }
        if b != b'\\' {
            out.push(b);
            i += 1;
            continue;
        }
        let at = start + i;
        let Some(&e) = bytes.get(i + 1) else {
            return Err(format!("'\\' at character {at} ends the string"));
        };
        i += 2;
        match e {
            b'n' => out.push(b'\n'),
            b'r' => out.push(b'\r'),
            b't' => out.push(b'\t'),
            b'a' => out.push(0x07),
            b'b' => out.push(0x08),
            b'f' => out.push(0x0c),
            b'v' => out.push(0x0b),
            b'\\' | b'\'' | b'"' | b'?' => out.push(e),
            b'0'..=b'7' => {
                let mut value = u32::from(e - b'0');
                let mut digits = 1;
                while digits < 3 && i < bytes.len() && (b'0'..=b'7').contains(&bytes[i]) {
                    value = value * 8 + u32::from(bytes[i] - b'0');
                    i += 1;
                    digits += 1;
                }
                let byte = u8::try_from(value)
                    .map_err(|_| format!("octal escape at character {at} is over \\377"))?;
                out.push(byte);
            }
            b'x' => {
                let mut value = 0u8;
                let mut digits = 0;
                while digits < 2 && i < bytes.len() && bytes[i].is_ascii_hexdigit() {
                    let d = (bytes[i] as char).to_digit(16).unwrap_or(0) as u8;
                    value = value * 16 + d;
                    i += 1;
                    digits += 1;
                }
                if digits == 0 {
                    return Err(format!("'\\x' at character {at} without hex digits"));
                }
                out.push(value);
            }
            other => {
                return Err(format!(
                    "unknown escape '\\{}' at character {at}",
                    other as char
                ))
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_byte_round_trips() {
        let all: Vec<u8> = (0..=255).collect();
        assert_eq!(unescape(&escape(&all)).unwrap(), all);
    }

    #[test]
    fn reference_forms() {
        assert_eq!(escape(&[4, 6]), r#""\004\006""#);
        assert_eq!(escape(b"a\"\\\n"), r#""a\"\\\n""#);
        assert_eq!(unescape(r#"\4\x0A\101"#).unwrap(), vec![4, 10, b'A']);
        assert_eq!(unescape(r#""\004\006""#).unwrap(), vec![4, 6]);
        assert!(unescape(r#""\400""#).is_err());
        assert!(unescape(r#""ab"#).is_err());
        assert!(unescape(r#"a\q"#).is_err());
        assert!(unescape(r#"a"b"#).is_err());
    }
}
