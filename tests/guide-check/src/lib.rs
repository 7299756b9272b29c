//! Checks the project's guide: runs the shell examples of `README.md` and
//! `docs/*.md` and compares their output with what the guide shows, and
//! checks that the files the guide shows are the committed files.
//!
//! A ```` ```console ```` block holds commands, each on a line starting with
//! `$ ` (a line ending in `\` goes on to the next), each followed by the
//! output it prints: its standard output, then its standard error. The
//! first output line may be `? N`, the exit status expected (0 when there
//! is none). In the output, `[..]` stands for any part of a line and `...`
//! alone on a line for any number of lines (the matching is snapbox's, as
//! trycmd's). A command that is only a variable assignment (`$ P=path`)
//! holds for the rest of its file, as in a shell.
//!
//! Each command runs in `bash` with `set -o pipefail` (so pipes, `<`
//! redirections and `$(...)` work as a reader types them), its working
//! directory a fresh directory for each file of the guide, whose entries
//! link to those of the repository root (paths such as `protos/...`
//! resolve, a file one command writes is there for the next, and files
//! the commands write stay out of the repository), the directories of the
//! programs under test first on the `PATH`, and a time limit.
//!
//! Blocks whose commands call a program the caller does not supply are
//! left to the test that supplies it ([`Guide::run_console_blocks`] says
//! which it ran).
//!
//! Why not trycmd: trycmd runs each `$` line of a Markdown file as one
//! program with its arguments, with no shell (no pipes, `<` or `>`, no
//! variables) and no standard input for Markdown cases, and the guide's
//! commands are shell lines that read the shipped example files. The
//! matching of output is trycmd's own engine, snapbox.
//!
//! A fenced block right after `<!-- file: PATH -->` must be the whole of
//! the repository's file `PATH`; after `<!-- excerpt: PATH -->`, lines that
//! appear in that file in the same order, one after the other.

use std::fmt::Write as _;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Time a single command may take.
pub const COMMAND_TIMEOUT: Duration = Duration::from_secs(120);

/// The repository root (this crate is `tests/guide-check/`).
pub fn repository_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .expect("the repository root")
}

/// One command of a console block and the output the guide shows for it.
#[derive(Debug, Clone)]
pub struct Example {
    /// The command, as typed (continuation lines joined with newlines).
    pub command: String,
    /// The exit status the guide expects.
    pub status: i32,
    /// The output the guide shows (may hold `[..]` and `...`).
    pub expected: String,
    /// Line of the command in its file (from 1).
    pub line: usize,
}

/// A ```` ```console ```` block.
#[derive(Debug, Clone)]
pub struct ConsoleBlock {
    /// Line of the opening fence (from 1).
    pub line: usize,
    /// Its commands, in order.
    pub examples: Vec<Example>,
}

/// A fenced block shown as a committed file or an excerpt of one.
#[derive(Debug, Clone)]
pub struct ShownFile {
    /// The file, relative to the repository root.
    pub path: String,
    /// True for `excerpt:`, false for `file:`.
    pub excerpt: bool,
    /// The block's text.
    pub text: String,
    /// Line of the opening fence (from 1).
    pub line: usize,
}

/// A Markdown file of the guide.
#[derive(Debug, Clone)]
pub struct Guide {
    /// Path relative to the repository root (for messages).
    pub name: String,
    /// Its text.
    pub text: String,
}

/// Every file of the guide: `README.md`, `CONTRIBUTING.md` and
/// `docs/*.md`, by name.
pub fn guide_files() -> Vec<Guide> {
    let root = repository_root();
    let mut names = vec!["README.md".to_string(), "CONTRIBUTING.md".to_string()];
    let mut docs: Vec<String> = std::fs::read_dir(root.join("docs"))
        .expect("docs/ exists")
        .map(|e| {
            e.expect("a docs/ entry")
                .file_name()
                .to_string_lossy()
                .into_owned()
        })
        .filter(|n| n.ends_with(".md"))
        .map(|n| format!("docs/{n}"))
        .collect();
    docs.sort();
    names.extend(docs);
    names
        .into_iter()
        .map(|name| Guide {
            text: std::fs::read_to_string(root.join(&name))
                .unwrap_or_else(|e| panic!("cannot read {name}: {e}")),
            name,
        })
        .collect()
}

/// The README.md of each crate of the workspace (`*/README.md`,
/// `examples/*/README.md`, `tests/*/README.md`), by name.
pub fn crate_readmes() -> Vec<Guide> {
    let root = repository_root();
    let mut names = Vec::new();
    for dir in ["", "examples/", "tests/"] {
        let Ok(entries) = std::fs::read_dir(root.join(dir)) else {
            continue;
        };
        for entry in entries.map_while(Result::ok) {
            let crate_dir = format!("{dir}{}", entry.file_name().to_string_lossy());
            if root.join(&crate_dir).join("Cargo.toml").is_file()
                && root.join(&crate_dir).join("README.md").is_file()
            {
                names.push(format!("{crate_dir}/README.md"));
            }
        }
    }
    names.sort();
    names
        .into_iter()
        .map(|name| Guide {
            text: std::fs::read_to_string(root.join(&name))
                .unwrap_or_else(|e| panic!("cannot read {name}: {e}")),
            name,
        })
        .collect()
}

/// A fenced block: its info string, first line number and lines.
struct Fence<'a> {
    info: &'a str,
    line: usize,
    body: Vec<&'a str>,
    /// The non-blank line before the opening fence.
    before: Option<&'a str>,
}

fn fences(text: &str) -> Vec<Fence<'_>> {
    let mut out = Vec::new();
    let mut current: Option<Fence> = None;
    let mut last_text: Option<&str> = None;
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        match &mut current {
            None => {
                if let Some(info) = trimmed.strip_prefix("```") {
                    current = Some(Fence {
                        info: info.trim(),
                        line: i + 1,
                        body: Vec::new(),
                        before: last_text,
                    });
                } else if !trimmed.is_empty() {
                    last_text = Some(trimmed);
                }
            }
            Some(fence) => {
                if trimmed == "```" {
                    out.push(current.take().unwrap());
                    last_text = None;
                } else {
                    fence.body.push(line);
                }
            }
        }
    }
    assert!(current.is_none(), "a fenced block is not closed");
    out
}

impl Guide {
    /// Its console blocks.
    pub fn console_blocks(&self) -> Vec<ConsoleBlock> {
        fences(&self.text)
            .into_iter()
            .filter(|f| f.info == "console")
            .map(|f| ConsoleBlock {
                line: f.line,
                examples: parse_console(&self.name, f.line, &f.body),
            })
            .collect()
    }

    /// Its blocks shown as committed files or excerpts of them.
    pub fn shown_files(&self) -> Vec<ShownFile> {
        fences(&self.text)
            .into_iter()
            .filter_map(|f| {
                let marker = f.before?.strip_prefix("<!--")?.strip_suffix("-->")?.trim();
                let (excerpt, path) = if let Some(p) = marker.strip_prefix("file:") {
                    (false, p)
                } else {
                    (true, marker.strip_prefix("excerpt:")?)
                };
                let mut text = f.body.join("\n");
                text.push('\n');
                Some(ShownFile {
                    path: path.trim().to_string(),
                    excerpt,
                    text,
                    line: f.line,
                })
            })
            .collect()
    }

    /// Runs the console blocks that call only the programs of `programs`
    /// (name and path of each) and common tools; returns the lines of the
    /// blocks it ran, and panics naming every example whose output differs.
    pub fn run_console_blocks(&self, programs: &[(&str, &Path)]) -> Vec<usize> {
        let names: Vec<&str> = programs.iter().map(|(n, _)| *n).collect();
        let mut path_dirs: Vec<PathBuf> = programs
            .iter()
            .map(|(_, p)| p.parent().expect("a program's directory").to_path_buf())
            .collect();
        path_dirs.extend(std::env::split_paths(
            &std::env::var_os("PATH").unwrap_or_default(),
        ));
        let path = std::env::join_paths(path_dirs).expect("a PATH");
        // One working directory for the file, as a reader's shell session.
        let sandbox = Sandbox::new().unwrap_or_else(|e| panic!("{}: {e}", self.name));
        let mut assignments = String::new();
        let mut ran = Vec::new();
        let mut failures = String::new();
        for block in self.console_blocks() {
            let runnable = block
                .examples
                .iter()
                .all(|e| uses_only(&e.command, &names) || is_assignment(&e.command));
            for example in &block.examples {
                if is_assignment(&example.command) {
                    assert!(
                        example.expected.is_empty() && example.status == 0,
                        "{}:{}: an assignment shows no output",
                        self.name,
                        example.line
                    );
                    assignments.push_str(&example.command);
                    assignments.push('\n');
                    continue;
                }
                if !runnable {
                    continue;
                }
                let script = format!("set -o pipefail\n{assignments}{}\n", example.command);
                if let Err(e) = check_example(&script, example, sandbox.dir(), &path) {
                    let _ = writeln!(
                        failures,
                        "{}:{}: `{}`\n{e}\n",
                        self.name, example.line, example.command
                    );
                }
            }
            if runnable {
                ran.push(block.line);
            }
        }
        assert!(failures.is_empty(), "{failures}");
        ran
    }
}

/// Programs of the project that the guide's commands may call; a block
/// calling one of them runs only where it is supplied.
pub const PROJECT_PROGRAMS: &[&str] = &["goby", "gobyd"];

/// True when `command` calls no project program outside `names`.
fn uses_only(command: &str, names: &[&str]) -> bool {
    words(command)
        .iter()
        .all(|w| !PROJECT_PROGRAMS.contains(&w.as_str()) || names.contains(&w.as_str()))
}

/// The words of a command line, split at blanks and shell operators.
fn words(command: &str) -> Vec<String> {
    command
        .split(|c: char| c.is_whitespace() || "|;&()<>`$\"'".contains(c))
        .filter(|w| !w.is_empty())
        .map(str::to_string)
        .collect()
}

fn is_assignment(command: &str) -> bool {
    let Some((name, value)) = command.split_once('=') else {
        return false;
    };
    !name.is_empty()
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        && !name.starts_with(|c: char| c.is_ascii_digit())
        && !value.contains(|c: char| c.is_whitespace() || "|;&<>`$()".contains(c))
}

fn parse_console(file: &str, fence_line: usize, body: &[&str]) -> Vec<Example> {
    let mut examples: Vec<Example> = Vec::new();
    let mut i = 0;
    while i < body.len() {
        let line = body[i];
        let line_no = fence_line + 1 + i;
        if let Some(command) = line.strip_prefix("$ ") {
            let mut command = command.to_string();
            while command.ends_with('\\') {
                i += 1;
                let next = body
                    .get(i)
                    .unwrap_or_else(|| panic!("{file}:{line_no}: a command ends in `\\`"));
                command.push('\n');
                command.push_str(next);
            }
            examples.push(Example {
                command,
                status: 0,
                expected: String::new(),
                line: line_no,
            });
        } else {
            let example = examples.last_mut().unwrap_or_else(|| {
                panic!("{file}:{line_no}: output before any `$ ` command in a console block")
            });
            match line.strip_prefix("? ") {
                Some(status) if example.expected.is_empty() => {
                    example.status = status.trim().parse().unwrap_or_else(|_| {
                        panic!("{file}:{line_no}: `? N` wants an exit status: {line}")
                    })
                }
                _ => {
                    example.expected.push_str(line);
                    example.expected.push('\n');
                }
            }
        }
        i += 1;
    }
    examples
}

/// Runs one example and compares; the reason when it differs.
fn check_example(
    script: &str,
    example: &Example,
    dir: &Path,
    path: &std::ffi::OsStr,
) -> Result<(), String> {
    let (status, stdout, stderr) = run_bash(script, dir, path)?;
    let mut actual = String::from_utf8_lossy(&stdout).into_owned();
    actual.push_str(&String::from_utf8_lossy(&stderr));
    let mut problems = String::new();
    if status != Some(example.status) {
        let _ = writeln!(
            problems,
            "exit status {status:?}, the guide says {}",
            example.status
        );
    }
    if !output_matches(&actual, &example.expected) {
        let _ = writeln!(
            problems,
            "output differs.\n--- the guide shows:\n{}--- the command printed:\n{actual}---",
            example.expected
        );
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(problems)
    }
}

/// Exit status (None when killed), standard output and standard error.
type Outcome = (Option<i32>, Vec<u8>, Vec<u8>);

/// Runs `script` with bash in `dir`.
fn run_bash(script: &str, dir: &Path, path: &std::ffi::OsStr) -> Result<Outcome, String> {
    use std::os::unix::process::CommandExt;
    let mut child = Command::new("bash")
        .arg("-c")
        .arg(script)
        .current_dir(dir)
        .env("PATH", path)
        .env_remove("RUST_BACKTRACE")
        .env_remove("DCCL_PASSPHRASE")
        .env_remove("GOBYD_PASSPHRASE")
        .env("NO_COLOR", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .process_group(0)
        .spawn()
        .map_err(|e| format!("cannot run bash: {e}"))?;
    let mut out = child.stdout.take().unwrap();
    let mut err = child.stderr.take().unwrap();
    let out_reader = std::thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = out.read_to_end(&mut buf);
        buf
    });
    let err_reader = std::thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = err.read_to_end(&mut buf);
        buf
    });
    let deadline = Instant::now() + COMMAND_TIMEOUT;
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(20)),
            Ok(None) => {
                // The whole process group: bash and what it started.
                let _ = Command::new("kill")
                    .arg("-KILL")
                    .arg(format!("-{}", child.id()))
                    .status();
                let _ = child.wait();
                return Err(format!(
                    "did not finish within {} s",
                    COMMAND_TIMEOUT.as_secs()
                ));
            }
            Err(e) => return Err(format!("cannot wait for bash: {e}")),
        }
    };
    let stdout = out_reader.join().expect("the stdout reader");
    let stderr = err_reader.join().expect("the stderr reader");
    Ok((status.code(), stdout, stderr))
}

/// A scratch directory whose entries link to the repository root's;
/// removed when dropped.
struct Sandbox {
    dir: PathBuf,
}

impl Sandbox {
    fn new() -> Result<Self, String> {
        use std::sync::atomic::{AtomicUsize, Ordering};
        static NEXT: AtomicUsize = AtomicUsize::new(0);
        let root = repository_root();
        let dir = std::env::temp_dir().join(format!(
            "guide-check-{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        for entry in std::fs::read_dir(&root).map_err(|e| e.to_string())? {
            let entry = entry.map_err(|e| e.to_string())?;
            let name = entry.file_name();
            if name == "target" || name == ".git" {
                continue;
            }
            std::os::unix::fs::symlink(entry.path(), dir.join(&name))
                .map_err(|e| format!("cannot link {}: {e}", entry.path().display()))?;
        }
        Ok(Sandbox { dir })
    }

    fn dir(&self) -> &Path {
        &self.dir
    }
}

impl Drop for Sandbox {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// Checks every block shown as a committed file or an excerpt of one;
/// returns the files shown, and panics naming every block that differs.
pub fn check_shown_files(guides: &[Guide]) -> Vec<PathBuf> {
    let root = repository_root();
    let mut failures = String::new();
    let mut files = Vec::new();
    for guide in guides {
        for shown in guide.shown_files() {
            let path = root.join(&shown.path);
            let Ok(content) = std::fs::read_to_string(&path) else {
                let _ = writeln!(
                    failures,
                    "{}:{}: shows {}, which does not exist",
                    guide.name, shown.line, shown.path
                );
                continue;
            };
            let same = if shown.excerpt {
                contains_lines(&content, &shown.text)
            } else {
                content == shown.text
            };
            if !same {
                let _ = writeln!(
                    failures,
                    "{}:{}: the block is not {} {}",
                    guide.name,
                    shown.line,
                    if shown.excerpt {
                        "an excerpt of"
                    } else {
                        "the whole of"
                    },
                    shown.path
                );
            }
            files.push(path);
        }
    }
    assert!(failures.is_empty(), "{failures}");
    files
}

/// The text of the fenced block right after the line `<!-- MARKER -->`.
pub fn block_after(guide: &Guide, marker: &str) -> Option<String> {
    let wanted = format!("<!-- {marker} -->");
    fences(&guide.text)
        .into_iter()
        .find(|f| f.before == Some(wanted.as_str()))
        .map(|f| {
            let mut text = f.body.join("\n");
            text.push('\n');
            text
        })
}

/// The marker of the installing block of `docs/README.md` (shell
/// completions and manual pages).
pub const INSTALL_MARKER: &str = "install: completions and manual pages";

/// The lines of `docs/README.md`'s installing block that `program` (`goby`
/// or `gobyd`) runs, with the `mkdir -p` lines before them, one script; a
/// test runs it with `HOME` in a scratch directory.
pub fn installing_commands(program: &str) -> String {
    let guide = guide_files()
        .into_iter()
        .find(|g| g.name == "docs/README.md")
        .expect("docs/README.md");
    let block = block_after(&guide, INSTALL_MARKER)
        .unwrap_or_else(|| panic!("no block after <!-- {INSTALL_MARKER} --> in docs/README.md"));
    let mut script = String::new();
    for line in block.lines() {
        let first = line.split_whitespace().next().unwrap_or("");
        if first == "mkdir" || first == program {
            script.push_str(line);
            script.push('\n');
        }
    }
    script
}

/// True when `actual` matches `expected`, with `[..]` and `...` as in the
/// console blocks.
pub fn output_matches(actual: &str, expected: &str) -> bool {
    let assert = snapbox::Assert::new()
        .action_env("GUIDE_CHECK")
        .normalize_paths(false);
    let (actual, expected) = assert.normalize(
        snapbox::Data::text(actual.to_string()),
        snapbox::Data::text(expected.to_string()),
    );
    actual.render() == expected.render()
}

/// The `#` anchors of a Markdown file's headings, as GitHub makes them:
/// lower case, punctuation but `-` and `_` dropped, spaces made `-`, a
/// repeated one numbered `-1`, `-2`, ... Headings inside fenced blocks are
/// not headings.
pub fn anchors(text: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let mut in_fence = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            in_fence = !in_fence;
            continue;
        }
        if in_fence || !line.starts_with('#') {
            continue;
        }
        let title = line.trim_start_matches('#');
        if !title.starts_with(' ') {
            continue;
        }
        let slug: String = title
            .trim()
            .to_lowercase()
            .chars()
            .filter(|c| c.is_alphanumeric() || *c == ' ' || *c == '-' || *c == '_')
            .map(|c| if c == ' ' { '-' } else { c })
            .collect();
        let mut anchor = slug.clone();
        let mut n = 0;
        while out.contains(&anchor) {
            n += 1;
            anchor = format!("{slug}-{n}");
        }
        out.push(anchor);
    }
    out
}

/// Checks every relative link of the guides (outside code): the file or
/// directory it names exists and, for `#anchor`, the file has that heading.
/// Returns the number of links checked; panics naming every broken one.
pub fn check_links(guides: &[Guide]) -> usize {
    let root = repository_root();
    let mut failures = String::new();
    let mut checked = 0;
    for guide in guides {
        let dir = Path::new(&guide.name).parent().unwrap_or(Path::new(""));
        let mut in_fence = false;
        for (i, line) in guide.text.lines().enumerate() {
            if line.trim_start().starts_with("```") {
                in_fence = !in_fence;
                continue;
            }
            if in_fence {
                continue;
            }
            for target in link_targets(line) {
                if target.contains("://") || target.starts_with("mailto:") {
                    continue;
                }
                checked += 1;
                let (file, anchor) = match target.split_once('#') {
                    Some((f, a)) => (f, Some(a)),
                    None => (target.as_str(), None),
                };
                let path = if file.is_empty() {
                    root.join(&guide.name)
                } else {
                    root.join(dir).join(file)
                };
                let where_ = format!("{}:{}", guide.name, i + 1);
                if !path.exists() {
                    let _ = writeln!(failures, "{where_}: {target}: no such file");
                    continue;
                }
                if let Some(anchor) = anchor {
                    let text = std::fs::read_to_string(&path).unwrap_or_default();
                    if !anchors(&text).iter().any(|a| a == anchor) {
                        let _ = writeln!(failures, "{where_}: {target}: no such section");
                    }
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures}");
    checked
}

/// The targets of the inline links `[text](target)` of a line, outside
/// inline code.
fn link_targets(line: &str) -> Vec<String> {
    // Inline code spans hold no links.
    let mut plain = String::new();
    for (i, part) in line.split('`').enumerate() {
        if i % 2 == 0 {
            plain.push_str(part);
        }
        plain.push(' ');
    }
    let mut out = Vec::new();
    let mut rest = plain.as_str();
    while let Some(at) = rest.find("](") {
        let after = &rest[at + 2..];
        match after.find(')') {
            Some(end) => {
                out.push(after[..end].trim().to_string());
                rest = &after[end..];
            }
            None => break,
        }
    }
    out
}

/// True when the lines of `excerpt` are lines of `content`, one after the
/// other.
fn contains_lines(content: &str, excerpt: &str) -> bool {
    let lines: Vec<&str> = content.lines().collect();
    let want: Vec<&str> = excerpt.lines().collect();
    !want.is_empty() && lines.windows(want.len()).any(|w| w == want.as_slice())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn console_blocks_parse_commands_statuses_and_output() {
        let guide = Guide {
            name: "x.md".into(),
            text: "text\n```console\n$ P=a/b\n$ echo 1 \\\n  2\n1 2\n$ false\n? 1\n```\n".into(),
        };
        let blocks = guide.console_blocks();
        assert_eq!(blocks.len(), 1);
        let e = &blocks[0].examples;
        assert_eq!(e.len(), 3);
        assert!(is_assignment(&e[0].command));
        assert_eq!(e[1].command, "echo 1 \\\n  2");
        assert_eq!(e[1].expected, "1 2\n");
        assert_eq!((e[2].status, e[2].expected.as_str()), (1, ""));
        assert!(!is_assignment(&e[1].command));
    }

    #[test]
    fn an_example_whose_output_differs_fails() {
        let path = std::env::var_os("PATH").unwrap();
        let sandbox = Sandbox::new().unwrap();
        let ok = |cmd: &str, expected: &str, status| {
            let e = Example {
                command: cmd.into(),
                status,
                expected: expected.into(),
                line: 1,
            };
            check_example(cmd, &e, sandbox.dir(), &path)
        };
        assert!(ok("echo hello world", "hello [..]\n", 0).is_ok());
        assert!(ok("printf 'a\\nb\\nc\\n'", "a\n...\n", 0).is_ok());
        assert!(ok("echo out; echo err >&2", "out\nerr\n", 0).is_ok());
        assert!(ok("echo hello", "goodbye\n", 0).is_err());
        assert!(ok("exit 3", "", 0).is_err());
        assert!(ok("exit 3", "", 3).is_ok());
        // Paths of the repository resolve in the sandbox.
        assert!(ok("test -f Cargo.toml && echo yes", "yes\n", 0).is_ok());
    }

    #[test]
    fn blocks_are_left_to_the_test_that_supplies_their_programs() {
        assert!(uses_only("echo x | goby dccl encode", &["goby"]));
        assert!(!uses_only("gobyd --check", &["goby"]));
        assert!(uses_only("ls gobyd/config", &["goby"]));
        assert!(uses_only("gobyd -c x | head -1", &["gobyd"]));
    }

    #[test]
    fn anchors_are_githubs() {
        let text = "# A tour of `goby dccl`\n```sh\n# not a heading\n```\n## `--check`\n\
                    ## Evaluation (thesis Table 3.2)\n## Beyond: x (`A_B`)\n## `--check`\n";
        assert_eq!(
            anchors(text),
            [
                "a-tour-of-goby-dccl",
                "--check",
                "evaluation-thesis-table-32",
                "beyond-x-a_b",
                "--check-1"
            ]
        );
        assert_eq!(
            link_targets("see [a](x.md#y) and `[b](no)` or [c](../z)"),
            ["x.md#y", "../z"]
        );
    }

    #[test]
    fn shown_files_are_marked_blocks() {
        let guide = Guide {
            name: "x.md".into(),
            text: "<!-- file: Cargo.toml -->\n```toml\n[workspace]\n```\n\n```sh\nno\n```\n".into(),
        };
        let shown = guide.shown_files();
        assert_eq!(shown.len(), 1);
        assert_eq!(shown[0].path, "Cargo.toml");
        assert!(!shown[0].excerpt);
        assert!(contains_lines("a\nb\nc\n", "b\nc\n"));
        assert!(!contains_lines("a\nb\nc\n", "a\nc\n"));
    }
}
