//! A guard run on every `.proto` source before it is parsed: brackets
//! (`{`, `<`, `[`, `(`) nested deeper than [`MAX_NESTING`] levels are refused
//! with the file, line and column, instead of letting a recursive parser
//! exhaust the stack (e.g. on an option value nested thousands of levels deep).

/// Deepest bracket nesting accepted in a `.proto` file (libprotobuf's parsers
/// stop at 100 levels of recursion as well).
pub const MAX_NESTING: usize = 100;

/// Where a source nests too deeply.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TooDeep {
    /// Line of the bracket that goes one level too deep, from 1.
    pub line: usize,
    /// Its column in characters, from 1.
    pub column: usize,
}

/// Scans `source` (skipping strings and comments) and returns where its
/// brackets first nest deeper than `max` levels, if they do.
pub fn find_too_deep(source: &str, max: usize) -> Option<TooDeep> {
    let mut depth = 0usize;
    let (mut line, mut column) = (1usize, 0usize);
    let mut chars = source.chars().peekable();
    while let Some(c) = chars.next() {
        column += 1;
        match c {
            '\n' => {
                line += 1;
                column = 0;
            }
            '/' if chars.peek() == Some(&'/') => {
                // Line comment: up to (not including) the newline.
                while chars.peek().is_some_and(|&n| n != '\n') {
                    chars.next();
                }
            }
            '/' if chars.peek() == Some(&'*') => {
                chars.next();
                column += 1;
                let mut star = false;
                for n in chars.by_ref() {
                    column += 1;
                    if n == '\n' {
                        line += 1;
                        column = 0;
                    }
                    if star && n == '/' {
                        break;
                    }
                    star = n == '*';
                }
            }
            '"' | '\'' => {
                // A string ends at the same quote (or, unterminated, at the newline).
                while let Some(&n) = chars.peek() {
                    if n == '\n' {
                        break;
                    }
                    chars.next();
                    column += 1;
                    if n == '\\' {
                        if chars.peek().is_some_and(|&e| e != '\n') {
                            chars.next();
                            column += 1;
                        }
                    } else if n == c {
                        break;
                    }
                }
            }
            '{' | '<' | '[' | '(' => {
                depth += 1;
                if depth > max {
                    return Some(TooDeep { line, column });
                }
            }
            '}' | '>' | ']' | ')' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    None
}

/// As [`find_too_deep`] with [`MAX_NESTING`], as an error message naming
/// `file`, the line and the column.
pub fn check(file: &str, source: &str) -> Result<(), String> {
    match find_too_deep(source, MAX_NESTING) {
        None => Ok(()),
        Some(at) => Err(format!(
            "{file}:{}:{}: brackets nested deeper than {MAX_NESTING} levels",
            at.line, at.column
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_brackets_outside_strings_and_comments() {
        let src =
            "message A { // {{{{\n  /* {{{{ */ optional string s = 1 [default = \"{{{\\\"{\"];\n}";
        assert_eq!(
            find_too_deep(src, 1),
            Some(TooDeep {
                line: 2,
                column: 36
            })
        );
        assert_eq!(find_too_deep(src, 2), None);
        assert_eq!(find_too_deep("a { b < c > }", 2), None);
        assert_eq!(
            find_too_deep("x\n  {{{", 2),
            Some(TooDeep { line: 2, column: 5 })
        );
    }
}
