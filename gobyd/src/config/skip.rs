//! Blanking one field of a configuration in protobuf text format, so that
//! reading can go on past a key it does not know and tell every such key
//! in one run instead of one a run.
//!
//! A field is its name (`name` or `[extension.name]`), then either `:` and
//! a value (a scalar token, one or more string literals, a `[ ... ]` list
//! or a `{ ... }` / `< ... >` section) or a section directly, then an
//! optional `,` or `;`. Comments (`#` to the end of the line) and string
//! literals are skipped over, so that braces inside them do not count.
//! The field is replaced by spaces, newlines kept: every other offset, and
//! so every line and column, stays where it was.

/// `text` with the field starting at byte `at` blanked; `None` when no
/// field starts there or its end is not found (an unbalanced section).
pub fn blank_field(text: &str, at: usize) -> Option<String> {
    let end = field_end(text.as_bytes(), at)?;
    let mut out = String::with_capacity(text.len());
    out.push_str(&text[..at]);
    out.extend(
        text[at..end]
            .chars()
            .map(|c| if c == '\n' || c == '\r' { c } else { ' ' }),
    );
    // Multi-byte characters turned into one space each: pad to keep the
    // offsets after the field.
    let blanked = out.len() - at;
    out.extend(std::iter::repeat_n(' ', (end - at).saturating_sub(blanked)));
    out.push_str(&text[end..]);
    Some(out)
}

/// Offset after the field starting at `at`.
fn field_end(b: &[u8], at: usize) -> Option<usize> {
    let mut i = at;
    if b.get(i) == Some(&b'[') {
        i = b[i..].iter().position(|&c| c == b']')? + i + 1;
    } else {
        let start = i;
        while b
            .get(i)
            .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_' || *c == b'.')
        {
            i += 1;
        }
        if i == start {
            return None;
        }
    }
    i = skip_space(b, i);
    match b.get(i)? {
        b':' => {
            i = skip_space(b, i + 1);
            i = value_end(b, i)?;
        }
        b'{' | b'<' => i = balanced_end(b, i)?,
        _ => return None,
    }
    let after = skip_space(b, i);
    if matches!(b.get(after), Some(b',' | b';')) {
        i = after + 1;
    }
    Some(i)
}

/// Offset after the value starting at `i`.
fn value_end(b: &[u8], mut i: usize) -> Option<usize> {
    match b.get(i)? {
        b'{' | b'<' | b'[' => balanced_end(b, i),
        b'"' | b'\'' => {
            // Adjacent literals are one string.
            loop {
                i = string_end(b, i)?;
                let next = skip_space(b, i);
                if !matches!(b.get(next), Some(b'"' | b'\'')) {
                    return Some(i);
                }
                i = next;
            }
        }
        _ => {
            let start = i;
            while b.get(i).is_some_and(|c| {
                !c.is_ascii_whitespace() && !matches!(c, b',' | b';' | b'}' | b'>' | b']' | b'#')
            }) {
                i += 1;
            }
            (i > start).then_some(i)
        }
    }
}

/// Offset after the section or list opened at `i`, strings and comments
/// skipped.
fn balanced_end(b: &[u8], mut i: usize) -> Option<usize> {
    let mut depth = 0usize;
    while let Some(&c) = b.get(i) {
        match c {
            b'{' | b'<' | b'[' => depth += 1,
            b'}' | b'>' | b']' => {
                depth = depth.checked_sub(1)?;
                if depth == 0 {
                    return Some(i + 1);
                }
            }
            b'"' | b'\'' => {
                i = string_end(b, i)?;
                continue;
            }
            b'#' => {
                i = line_end(b, i);
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    None
}

/// Offset after the string literal opened at `i` (escapes honoured).
fn string_end(b: &[u8], i: usize) -> Option<usize> {
    let quote = b[i];
    let mut j = i + 1;
    while let Some(&c) = b.get(j) {
        match c {
            b'\\' => j += 2,
            b'\n' => return None,
            c if c == quote => return Some(j + 1),
            _ => j += 1,
        }
    }
    None
}

fn line_end(b: &[u8], i: usize) -> usize {
    b[i..]
        .iter()
        .position(|&c| c == b'\n')
        .map_or(b.len(), |p| i + p)
}

/// Offset of the first byte at or after `i` that is neither white space
/// nor in a comment.
fn skip_space(b: &[u8], mut i: usize) -> usize {
    loop {
        match b.get(i) {
            Some(c) if c.is_ascii_whitespace() => i += 1,
            Some(b'#') => i = line_end(b, i),
            _ => return i,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blanked(text: &str, field: &str) -> String {
        let at = text.find(field).unwrap();
        let out = blank_field(text, at).unwrap();
        assert_eq!(out.len(), text.len());
        out
    }

    #[test]
    fn each_form_of_field_is_blanked_whole_and_nothing_else() {
        assert_eq!(
            blanked("a: 1\nfoo: 2\nb: 3\n", "foo"),
            "a: 1\n      \nb: 3\n"
        );
        assert_eq!(
            blanked("foo { x: \"}\" # }\n y { } }\nb: 3", "foo"),
            "                \n        \nb: 3"
        );
        assert_eq!(blanked("foo: [1, 2], b: 3", "foo"), "             b: 3");
        assert_eq!(blanked("foo: \"a\" 'b'; b: 3", "foo"), "              b: 3");
        assert_eq!(blanked("foo: < x: 1 > b: 3", "foo"), "              b: 3");
        assert_eq!(blanked("[a.b.c] { } b: 3", "[a.b"), "            b: 3");
        assert_eq!(blanked("s { foo: ENUM }", "foo"), "s {           }");
        assert!(blank_field("foo { ", 0).is_none());
        assert!(blank_field("= 1", 0).is_none());
        let long = "foo: \"été\"";
        assert_eq!(
            blanked(&format!("{long}\nb: 1"), "foo"),
            format!("{}\nb: 1", " ".repeat(long.len()))
        );
    }
}
