//! Tokens of the Lua 5.3 language as DCCL condition scripts write them:
//! names, numbers (decimal and hexadecimal, integer and float), short and
//! long strings with every escape, comments and operators.

use std::sync::Arc;

/// One token.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Tok {
    /// A name or a keyword.
    Name(Arc<str>),
    /// A string literal (bytes: escapes may produce any byte).
    Str(Arc<[u8]>),
    /// An integer literal.
    Int(i64),
    /// A float literal.
    Num(f64),
    /// An operator or punctuation.
    Op(&'static str),
    /// The end of the script.
    Eof,
}

/// Operators and punctuation, longest first.
const OPS: &[&str] = &[
    "...", "..", "==", "~=", "<=", ">=", "<<", ">>", "//", "::", "+", "-", "*", "/", "%", "^", "#",
    "&", "~", "|", "<", ">", "=", "(", ")", "{", "}", "[", "]", ";", ":", ",", ".",
];

/// Splits `src` into tokens; an error names the byte offset.
pub(crate) fn tokens(src: &str) -> Result<Vec<Tok>, String> {
    let b = src.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c.is_ascii_whitespace() {
            i += 1;
        } else if b[i..].starts_with(b"--") {
            i += 2;
            if let Some((_, end)) = long_bracket(b, i)? {
                i = end;
            } else {
                while i < b.len() && b[i] != b'\n' {
                    i += 1;
                }
            }
        } else if c.is_ascii_alphabetic() || c == b'_' {
            let start = i;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                i += 1;
            }
            out.push(Tok::Name(Arc::from(&src[start..i])));
        } else if c.is_ascii_digit() || (c == b'.' && b.get(i + 1).is_some_and(u8::is_ascii_digit))
        {
            let (tok, end) = number(src, i)?;
            out.push(tok);
            i = end;
        } else if c == b'"' || c == b'\'' {
            let (s, end) = short_string(b, i)?;
            out.push(Tok::Str(Arc::from(s)));
            i = end;
        } else if c == b'[' && matches!(b.get(i + 1), Some(b'[' | b'=')) {
            match long_bracket(b, i)? {
                Some((s, end)) => {
                    out.push(Tok::Str(Arc::from(s)));
                    i = end;
                }
                None => {
                    out.push(Tok::Op("["));
                    i += 1;
                }
            }
        } else if let Some(op) = OPS.iter().find(|op| b[i..].starts_with(op.as_bytes())) {
            out.push(Tok::Op(op));
            i += op.len();
        } else {
            return Err(format!(
                "unexpected character {:?} at offset {i}",
                c as char
            ));
        }
    }
    out.push(Tok::Eof);
    Ok(out)
}

/// A long bracket `[[...]]` or `[==[...]==]` at `i`: its text (a first line
/// break dropped) and the offset after it; `None` when `i` opens none.
fn long_bracket(b: &[u8], i: usize) -> Result<Option<(Vec<u8>, usize)>, String> {
    if b.get(i) != Some(&b'[') {
        return Ok(None);
    }
    let mut j = i + 1;
    while b.get(j) == Some(&b'=') {
        j += 1;
    }
    if b.get(j) != Some(&b'[') {
        return Ok(None);
    }
    let level = j - i - 1;
    let mut start = j + 1;
    if b[start..].starts_with(b"\r\n") || b[start..].starts_with(b"\n\r") {
        start += 2;
    } else if matches!(b.get(start), Some(b'\n' | b'\r')) {
        start += 1;
    }
    let mut close = vec![b']'];
    close.extend(std::iter::repeat_n(b'=', level));
    close.push(b']');
    let end = b[start..]
        .windows(close.len())
        .position(|w| w == close.as_slice())
        .ok_or_else(|| format!("unfinished long string or comment at offset {i}"))?;
    Ok(Some((
        b[start..start + end].to_vec(),
        start + end + close.len(),
    )))
}

/// A quoted string at `i`, escapes resolved.
fn short_string(b: &[u8], i: usize) -> Result<(Vec<u8>, usize), String> {
    let quote = b[i];
    let mut out = Vec::new();
    let mut j = i + 1;
    let unfinished = || format!("unfinished string at offset {i}");
    loop {
        let c = *b.get(j).ok_or_else(unfinished)?;
        j += 1;
        if c == quote {
            return Ok((out, j));
        }
        if c == b'\n' || c == b'\r' {
            return Err(unfinished());
        }
        if c != b'\\' {
            out.push(c);
            continue;
        }
        let e = *b.get(j).ok_or_else(unfinished)?;
        j += 1;
        match e {
            b'a' => out.push(7),
            b'b' => out.push(8),
            b'f' => out.push(12),
            b'n' | b'\n' => out.push(b'\n'),
            b'r' => out.push(b'\r'),
            b't' => out.push(b'\t'),
            b'v' => out.push(11),
            b'\\' | b'"' | b'\'' => out.push(e),
            b'x' => {
                let hex = b
                    .get(j..j + 2)
                    .and_then(|h| std::str::from_utf8(h).ok())
                    .and_then(|h| u8::from_str_radix(h, 16).ok())
                    .ok_or_else(|| format!("hexadecimal digit expected at offset {j}"))?;
                out.push(hex);
                j += 2;
            }
            b'z' => {
                while b.get(j).is_some_and(u8::is_ascii_whitespace) {
                    j += 1;
                }
            }
            b'u' => {
                let close = b[j..].iter().position(|&c| c == b'}');
                let code = (b.get(j) == Some(&b'{'))
                    .then_some(close)
                    .flatten()
                    .and_then(|c| std::str::from_utf8(&b[j + 1..j + c]).ok())
                    .and_then(|h| u32::from_str_radix(h, 16).ok())
                    .and_then(char::from_u32)
                    .ok_or_else(|| format!("bad \\u escape at offset {j}"))?;
                let mut buf = [0u8; 4];
                out.extend_from_slice(code.encode_utf8(&mut buf).as_bytes());
                j += close.unwrap_or(0) + 1;
            }
            d if d.is_ascii_digit() => {
                let mut v = u32::from(d - b'0');
                for _ in 0..2 {
                    match b.get(j) {
                        Some(&d) if d.is_ascii_digit() => {
                            v = v * 10 + u32::from(d - b'0');
                            j += 1;
                        }
                        _ => break,
                    }
                }
                out.push(u8::try_from(v).map_err(|_| format!("escape too large at offset {j}"))?);
            }
            _ => return Err(format!("invalid escape sequence at offset {}", j - 2)),
        }
    }
}

/// A numeral at `i`: the token and the offset after it.
fn number(src: &str, i: usize) -> Result<(Tok, usize), String> {
    let b = src.as_bytes();
    let hex = b[i..].starts_with(b"0x") || b[i..].starts_with(b"0X");
    let mut j = if hex { i + 2 } else { i };
    let (exp_lo, exp_hi) = if hex { (b'p', b'P') } else { (b'e', b'E') };
    while j < b.len() {
        let c = b[j];
        let digit = if hex {
            c.is_ascii_hexdigit()
        } else {
            c.is_ascii_digit()
        };
        if digit || c == b'.' {
            j += 1;
        } else if c == exp_lo || c == exp_hi {
            j += 1;
            if matches!(b.get(j), Some(b'+' | b'-')) {
                j += 1;
            }
        } else {
            break;
        }
    }
    if b.get(j)
        .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_')
    {
        return Err(format!("malformed number near offset {i}"));
    }
    let text = &src[i..j];
    let tok =
        super::number::parse_numeral(text).ok_or_else(|| format!("malformed number '{text}'"))?;
    Ok((tok, j))
}
