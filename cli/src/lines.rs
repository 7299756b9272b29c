//! Line-by-line processing of an input stream, with a report for each line
//! that cannot be handled.

use std::io::{self, BufRead, Write};

use crate::CliError;

/// Why one input line could not be handled.
pub(crate) enum LineError {
    /// The line is bad; it is reported and processing goes on.
    Bad(String),
    /// Processing cannot go on (e.g. the output cannot be written).
    Fatal(CliError),
}

impl From<io::Error> for LineError {
    fn from(e: io::Error) -> Self {
        LineError::Fatal(CliError::Output(e))
    }
}

/// Writes a warning about input line `number` on `stderr`, as
/// `line N: warning: <message>`; warnings do not make the line bad.
pub(crate) fn warn(stderr: &mut dyn Write, number: usize, message: &str) -> Result<(), LineError> {
    writeln!(stderr, "line {number}: warning: {message}")?;
    Ok(())
}

/// Calls `handle(line_number, line, stderr)` on each non-blank line of
/// `input`, with surrounding whitespace removed (`stderr` is there for
/// [`warn`]). Line numbers start at 1 and count blank lines too, so that they
/// match the input. Each bad line is reported on `stderr` as
/// `line N: <error>`; returns how many there were.
pub(crate) fn for_each_line(
    input: &mut dyn BufRead,
    stderr: &mut dyn Write,
    mut handle: impl FnMut(usize, &str, &mut dyn Write) -> Result<(), LineError>,
) -> Result<usize, CliError> {
    let mut buf = Vec::new();
    let mut number = 0usize;
    let mut bad = 0usize;
    loop {
        buf.clear();
        if input.read_until(b'\n', &mut buf).map_err(CliError::Input)? == 0 {
            break;
        }
        number += 1;
        let result = match std::str::from_utf8(&buf) {
            Ok(text) => {
                let line = text.trim();
                if line.is_empty() {
                    continue;
                }
                handle(number, line, &mut *stderr)
            }
            Err(e) => Err(LineError::Bad(format!("not valid UTF-8: {e}"))),
        };
        match result {
            Ok(()) => {}
            Err(LineError::Bad(message)) => {
                bad += 1;
                writeln!(stderr, "line {number}: {message}")?;
            }
            Err(LineError::Fatal(e)) => return Err(e),
        }
    }
    Ok(bad)
}
