//! MOOS `KEY = value` lines among the protobuf text of a mission file's
//! `ProcessConfig` block (`AppTick = 4`, `modem_id = 2`).
//!
//! Only lines at the top level of the block are MOOS lines (inside a
//! section `=` has no meaning), and only when the text before the first
//! `=` is a bare name: `translator_entry { format: "A=%1%" }` is not one.

use super::{tokens, Token};

/// A `KEY = value` line at the top level of a block.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct MoosLine {
    /// The key as written.
    pub key: String,
    /// Byte offset of the key in the text.
    pub key_offset: usize,
    /// The value, blanks at both ends and a `#` comment removed (quotes,
    /// when written, kept).
    pub value: String,
    /// Byte offset of the value (of the end of the line when it is empty).
    pub value_offset: usize,
}

/// The MOOS lines of `text` (protobuf text format with `#` comments), and
/// the text with each of them blanked: every byte of the line before its
/// comment a space, so that the rest keeps its lines, columns and byte
/// offsets.
pub(crate) fn take(text: &str) -> (String, Vec<MoosLine>) {
    let mut lines = Vec::new();
    let mut blanks: Vec<(usize, usize)> = Vec::new();
    let mut depth = 0usize;
    let mut skip_until = 0usize;
    for token in tokens(text) {
        let offset = match token {
            Token::Punct(_, at) | Token::Str(at) | Token::Word(_, at) => at,
        };
        if offset < skip_until {
            continue;
        }
        match token {
            Token::Punct(b'{' | b'<' | b'[', _) => depth += 1,
            Token::Punct(b'}' | b'>' | b']', _) => depth = depth.saturating_sub(1),
            Token::Word(_, at) if depth == 0 && starts_line(text, at) => {
                if let Some((line, end)) = moos_line(text, at) {
                    blanks.push((at, end));
                    lines.push(line);
                    skip_until = end;
                }
            }
            _ => {}
        }
    }
    let mut out = String::with_capacity(text.len());
    let mut copied = 0;
    for (start, end) in blanks {
        out.push_str(&text[copied..start]);
        out.push_str(&" ".repeat(end - start));
        copied = end;
    }
    out.push_str(&text[copied..]);
    (out, lines)
}

/// Whether only blanks come before `at` on its line.
fn starts_line(text: &str, at: usize) -> bool {
    text[..at]
        .rsplit('\n')
        .next()
        .unwrap_or("")
        .chars()
        .all(char::is_whitespace)
}

/// The MOOS line starting at `at`, if the line is one, and where its text
/// ends (before a comment or the line break).
fn moos_line(text: &str, at: usize) -> Option<(MoosLine, usize)> {
    let line_end = text[at..].find('\n').map_or(text.len(), |n| at + n);
    let line = &text[at..line_end];
    let key_len = line
        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .unwrap_or(line.len());
    if key_len == 0 || line.as_bytes()[0].is_ascii_digit() {
        return None;
    }
    let after_key = &line[key_len..];
    let spaces = after_key.len() - after_key.trim_start_matches([' ', '\t']).len();
    if !after_key[spaces..].starts_with('=') {
        return None;
    }
    let value_start = key_len + spaces + 1;
    let text_end = comment_start(&line[value_start..]).map_or(line.len(), |c| value_start + c);
    let raw = &line[value_start..text_end];
    let value = raw.trim();
    let lead = raw.len() - raw.trim_start().len();
    let end = at + value_start + raw.trim_end().len();
    Some((
        MoosLine {
            key: line[..key_len].to_string(),
            key_offset: at,
            value: value.to_string(),
            value_offset: at + value_start + lead,
        },
        end.max(at + value_start),
    ))
}

/// Byte offset of a `#` comment outside quotes in `text`.
fn comment_start(text: &str) -> Option<usize> {
    let mut quote: Option<char> = None;
    let mut escaped = false;
    for (i, c) in text.char_indices() {
        match quote {
            Some(_) if escaped => escaped = false,
            Some(_) if c == '\\' => escaped = true,
            Some(q) if c == q => quote = None,
            Some(_) => {}
            None if c == '"' || c == '\'' => quote = Some(c),
            None if c == '#' => return Some(i),
            None => {}
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn top_level_key_equals_value_lines_are_taken_and_blanked() {
        let text = "  AppTick = 4   # polled\n  modem_id: 2\n  CommsTick=8\n  mac {\n    x = 1\n  }\n  data_dir = \"/tmp/a b\"\n  translator_entry { format: \"A=%1%\" }\n  empty =\n";
        let (blanked, lines) = take(text);
        assert_eq!(blanked.len(), text.len());
        assert_eq!(blanked.lines().count(), text.lines().count());
        let keys: Vec<(&str, &str)> = lines
            .iter()
            .map(|l| (l.key.as_str(), l.value.as_str()))
            .collect();
        // Inside a section a line is not a MOOS line; a string's `=` is not one.
        assert_eq!(
            keys,
            [
                ("AppTick", "4"),
                ("CommsTick", "8"),
                ("data_dir", "\"/tmp/a b\""),
                ("empty", "")
            ]
        );
        assert_eq!(&text[lines[0].value_offset..][..1], "4");
        assert_eq!(&text[lines[2].key_offset..][..8], "data_dir");
        let first: &str = blanked.lines().next().unwrap();
        assert_eq!(first, "                # polled");
        assert!(blanked.contains("modem_id: 2") && blanked.contains("x = 1"));
        assert!(!blanked.contains("CommsTick"));
    }
}
