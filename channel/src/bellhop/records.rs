//! Fortran list-directed input, as the Acoustics Toolbox reads its text
//! files (`READ( unit, * ) ...`).
//!
//! Each read starts on a new line and takes values separated by blanks or
//! commas, over as many lines as it needs; a `/` ends it early, leaving the
//! remaining items as they were (BELLHOP relies on that: `0.0 1500.0 /`
//! keeps the density and attenuation of the line before). Whatever follows
//! the last value on the line a read ends on is skipped, which is how files
//! carry `! comments`. Strings are quoted with `'` or `"`. A repeat count
//! `3*1500.0` stands for three values.

use super::ParseError;

/// One value of a list-directed read, with the line it came from (1-based).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Value {
    pub text: String,
    pub quoted: bool,
    pub line: usize,
}

/// A text file read record by record.
pub(crate) struct Records<'a> {
    file: String,
    lines: Vec<&'a str>,
    /// Index of the next line a read starts on.
    next: usize,
}

impl<'a> Records<'a> {
    /// The records of `text`, named `file` in errors.
    pub fn new(file: &str, text: &'a str) -> Self {
        Records {
            file: file.to_string(),
            lines: text.lines().collect(),
            next: 0,
        }
    }

    /// The line the next read starts on (1-based), for errors at the end of
    /// a file.
    pub fn line(&self) -> usize {
        (self.next + 1).min(self.lines.len().max(1))
    }

    /// An error at `line` about `field`.
    pub fn error(&self, line: usize, field: &str, message: impl Into<String>) -> ParseError {
        ParseError {
            file: self.file.clone(),
            line,
            field: field.to_string(),
            message: message.into(),
        }
    }

    /// Reads up to `max` values starting on the next line, stopping early
    /// at a `/`. Blank lines before the first value are skipped. `field`
    /// names what is read, for the error when the file ends first.
    pub fn read(&mut self, max: usize, field: &str) -> Result<Vec<Value>, ParseError> {
        let mut values = Vec::new();
        while values.len() < max {
            let Some(line) = self.lines.get(self.next) else {
                if values.is_empty() {
                    return Err(self.error(
                        self.lines.len().max(1),
                        field,
                        "the file ends before this field",
                    ));
                }
                break;
            };
            let number = self.next + 1;
            self.next += 1;
            match split_line(line, number, max - values.len(), &mut values) {
                Ok(true) => break, // a slash ended the read
                Ok(false) => {}
                Err(message) => return Err(self.error(number, field, message)),
            }
        }
        Ok(values)
    }

    /// The quoted string the next read would start with, and its line
    /// (1-based), when it starts with one.
    pub fn next_quoted(&self) -> Option<(String, usize)> {
        for (i, line) in self.lines.iter().enumerate().skip(self.next) {
            let mut values = Vec::new();
            match split_line(line, i + 1, 1, &mut values) {
                Ok(_) if values.is_empty() => continue,
                Ok(_) => return values.pop().filter(|v| v.quoted).map(|v| (v.text, v.line)),
                Err(_) => return None,
            }
        }
        None
    }

    /// Reads exactly one value.
    pub fn read_one(&mut self, field: &str) -> Result<Value, ParseError> {
        let line = self.line();
        self.read(1, field)?
            .into_iter()
            .next()
            .ok_or_else(|| self.error(line, field, "no value before the '/'"))
    }

    /// Reads a count and that many numbers after it in the same record
    /// (`3 10.0 20.0 30.0`).
    pub fn read_counted(&mut self, field: &str) -> Result<Vec<f64>, ParseError> {
        let start = self.next;
        let line = self.line();
        let first = self.read_one(field)?;
        let n = self.integer(&first, field)?;
        if !(0..=100_000_000).contains(&n) {
            return Err(self.error(line, field, format!("{n} is not a count")));
        }
        self.next = start;
        let values = self.read_numbers(n as usize + 1, field)?;
        if values.len() != n as usize + 1 {
            return Err(self.error(
                line,
                field,
                format!("{n} values announced, {} given", values.len() - 1),
            ));
        }
        Ok(values[1..].iter().map(|v| v.0).collect())
    }

    /// Converts `value` to a finite number.
    pub fn number(&self, value: &Value, field: &str) -> Result<f64, ParseError> {
        parse_number(&value.text)
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                self.error(
                    value.line,
                    field,
                    format!("'{}' is not a finite number", value.text),
                )
            })
    }

    /// Converts `value` to a whole number.
    pub fn integer(&self, value: &Value, field: &str) -> Result<i64, ParseError> {
        let v = self.number(value, field)?;
        if v.fract() != 0.0 || v.abs() > 1e12 {
            return Err(self.error(
                value.line,
                field,
                format!("'{}' is not a whole number", value.text),
            ));
        }
        Ok(v as i64)
    }

    /// Reads one number.
    pub fn read_number(&mut self, field: &str) -> Result<f64, ParseError> {
        let v = self.read_one(field)?;
        self.number(&v, field)
    }

    /// Reads a count of at least `min` and at most `max`.
    pub fn read_count(&mut self, field: &str, min: i64, max: i64) -> Result<usize, ParseError> {
        let v = self.read_one(field)?;
        let n = self.integer(&v, field)?;
        if n < min || n > max {
            return Err(self.error(
                v.line,
                field,
                format!("{n} is out of range ({min} to {max})"),
            ));
        }
        Ok(n as usize)
    }

    /// Reads up to `max` numbers (a `/` may end the list early).
    pub fn read_numbers(
        &mut self,
        max: usize,
        field: &str,
    ) -> Result<Vec<(f64, usize)>, ParseError> {
        let values = self.read(max, field)?;
        values
            .iter()
            .map(|v| self.number(v, field).map(|n| (n, v.line)))
            .collect()
    }
}

/// Splits one line into values, appending at most `room` of them; true
/// when a `/` ended the read.
fn split_line(
    line: &str,
    number: usize,
    room: usize,
    out: &mut Vec<Value>,
) -> Result<bool, String> {
    let mut chars = line.char_indices().peekable();
    let mut taken = 0;
    while let Some(&(_, c)) = chars.peek() {
        if taken == room {
            return Ok(false);
        }
        match c {
            ' ' | '\t' | ',' | '\r' => {
                chars.next();
            }
            '/' => return Ok(true),
            '\'' | '"' => {
                chars.next();
                let mut text = String::new();
                let mut closed = false;
                while let Some((_, d)) = chars.next() {
                    if d == c {
                        // A doubled quote stands for one.
                        if chars.peek().map(|&(_, e)| e) == Some(c) {
                            chars.next();
                            text.push(c);
                            continue;
                        }
                        closed = true;
                        break;
                    }
                    text.push(d);
                }
                if !closed {
                    return Err(format!("unterminated string {c}{text}"));
                }
                out.push(Value {
                    text,
                    quoted: true,
                    line: number,
                });
                taken += 1;
            }
            _ => {
                let mut text = String::new();
                while let Some(&(_, d)) = chars.peek() {
                    if matches!(d, ' ' | '\t' | ',' | '/' | '\r') {
                        break;
                    }
                    text.push(d);
                    chars.next();
                }
                // r*value repeats the value r times.
                if let Some((count, value)) = text.split_once('*') {
                    if let Ok(count) = count.parse::<usize>() {
                        if value.is_empty() || count == 0 || count > 1_000_000 {
                            return Err(format!("unsupported repeat '{text}'"));
                        }
                        for _ in 0..count.min(room - taken) {
                            out.push(Value {
                                text: value.to_string(),
                                quoted: false,
                                line: number,
                            });
                            taken += 1;
                        }
                        continue;
                    }
                }
                out.push(Value {
                    text,
                    quoted: false,
                    line: number,
                });
                taken += 1;
            }
        }
    }
    Ok(false)
}

/// A Fortran real: `1.5`, `1.5e3`, `1.5D3`, `.5`, `-2`.
pub(crate) fn parse_number(text: &str) -> Option<f64> {
    let t = text.replace(['d', 'D'], "e");
    t.parse::<f64>().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_slash_ends_a_read_and_the_rest_of_the_line_is_skipped() {
        let mut r = Records::new("t.env", "1 2 / 3\n4 5 ! comment\n'CVW'  ! opt\n6,7\n8\n");
        let v = r.read(3, "a").unwrap();
        assert_eq!(v.len(), 2);
        let v = r.read_numbers(1, "b").unwrap();
        assert_eq!(v, vec![(4.0, 2)]);
        let v = r.read_one("c").unwrap();
        assert!(v.quoted && v.text == "CVW");
        let v = r.read_numbers(3, "d").unwrap();
        assert_eq!(v, vec![(6.0, 4), (7.0, 4), (8.0, 5)]);
        let e = r.read_one("e").unwrap_err();
        assert!(e.to_string().contains("e"), "{e}");
    }

    #[test]
    fn repeats_and_fortran_exponents() {
        let mut r = Records::new("t", "2*1.5D3 -0.5e1\n");
        let v = r.read_numbers(3, "x").unwrap();
        assert_eq!(
            v.iter().map(|p| p.0).collect::<Vec<_>>(),
            [1500.0, 1500.0, -5.0]
        );
    }

    #[test]
    fn garbage_is_an_error_naming_line_and_field() {
        let mut r = Records::new("x.bty", "\n\n12 abc\n");
        let v = r.read_numbers(2, "bathymetry point 1").unwrap_err();
        assert_eq!(v.line, 3);
        assert!(v.to_string().contains("x.bty:3"), "{v}");
        assert!(v.to_string().contains("bathymetry point 1"), "{v}");
    }
}
