//! `goby completions SHELL` and `goby man DIR`: shell completion scripts and
//! manual pages, generated from the command line's own definition
//! (`clap_complete`, `clap_mangen`), so they always match the installed
//! `goby`.

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::{Args, Command, CommandFactory};
use clap_complete::Shell;

use crate::{CliError, GobyCli, Status};

/// Options of `goby completions`.
#[derive(Debug, Args)]
#[command(
    long_about = "Print a shell completion script for goby on standard output.\n\n\
    The directory the script is written into must exist (mkdir -p).\n\n\
    Examples:\n  \
    mkdir -p ~/.local/share/bash-completion/completions\n  \
    goby completions bash > ~/.local/share/bash-completion/completions/goby\n  \
    mkdir -p ~/.zfunc && goby completions zsh > ~/.zfunc/_goby      # with fpath+=~/.zfunc before compinit\n  \
    mkdir -p ~/.config/fish/completions && goby completions fish > ~/.config/fish/completions/goby.fish\n  \
    goby completions powershell >> $PROFILE"
)]
pub struct CompletionsArgs {
    /// The shell.
    #[arg(value_name = "SHELL")]
    pub shell: Shell,
}

/// Options of `goby man`.
#[derive(Debug, Args)]
#[command(
    long_about = "Write goby's manual pages into DIR (created if missing): goby.1 and \
    one page per subcommand (goby-dccl.1, goby-moos-poke.1, ...). The paths written are \
    printed, one a line. Called by another name (the Debian package's goby-rs), the \
    pages, and the completion scripts, are for that name (goby-rs.1, goby-rs-dccl.1, ...).\n\n\
    ~/.cargo/share/man/man1 is where man finds them for a user with ~/.cargo/bin on \
    the PATH (man searches ../share/man beside each PATH directory; see manpath).\n\n\
    Example:\n  \
    goby man ~/.cargo/share/man/man1 && man goby-moos-spy"
)]
pub struct ManArgs {
    /// Directory to write the pages into.
    #[arg(value_name = "DIR")]
    pub dir: PathBuf,
}

/// Writes the completion script of `cmd`, installed as `bin`, for `shell`.
pub fn write_completions(shell: Shell, mut cmd: Command, bin: &str, out: &mut dyn Write) {
    clap_complete::generate(shell, &mut cmd, bin, out);
}

/// `roff` with each `code` span of the help texts (Markdown backticks) in
/// bold, as manual pages show commands; unpaired backticks are kept.
fn code_in_bold(roff: &str) -> String {
    if roff.matches('`').count() % 2 == 1 {
        return roff.to_string();
    }
    let parts = roff.split('`').enumerate();
    parts
        .map(|(i, part)| match i % 2 {
            1 => format!("\\fB{part}\\fR"),
            _ => part.to_string(),
        })
        .collect()
}

/// Writes the manual page of `cmd` and of each of its visible subcommands,
/// at every level (`goby-moos-poke.1`), into `dir`; returns the paths
/// written.
pub fn write_man_pages(cmd: Command, dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    fn pages(cmd: Command, dir: &Path, written: &mut Vec<PathBuf>) -> std::io::Result<()> {
        let page = clap_mangen::Man::new(cmd.clone()).generate_to(dir)?;
        let roff = std::fs::read_to_string(&page)?;
        std::fs::write(&page, code_in_bold(&roff))?;
        written.push(page);
        for sub in cmd.get_subcommands().filter(|s| !s.is_hide_set()) {
            pages(sub.clone(), dir, written)?;
        }
        Ok(())
    }
    // Built, so that subcommands know their full names (goby-moos-poke).
    let mut cmd = cmd.disable_help_subcommand(true);
    cmd.build();
    let mut written = Vec::new();
    pages(cmd, dir, &mut written)?;
    Ok(written)
}

/// The name the tool was called by: `goby`, or `goby-rs` through the Debian
/// package's link (docs/vehicle.md), so that its completions and manual
/// pages are for the command the user types.
pub fn called_name() -> &'static str {
    let called = std::env::args_os()
        .next()
        .and_then(|a| Some(Path::new(&a).file_name()?.to_str()?.to_owned()));
    match called {
        Some(name) if !name.is_empty() => Box::leak(name.into_boxed_str()),
        _ => "goby",
    }
}

/// Runs `goby completions`.
pub fn completions(args: &CompletionsArgs, stdout: &mut dyn Write) -> Result<Status, CliError> {
    let mut script = Vec::new();
    let name = called_name();
    write_completions(args.shell, GobyCli::command().name(name), name, &mut script);
    stdout.write_all(&script)?;
    Ok(Status::Ok)
}

/// Runs `goby man`.
pub fn man(args: &ManArgs, stdout: &mut dyn Write) -> Result<Status, CliError> {
    let dir = &args.dir;
    std::fs::create_dir_all(dir).map_err(|e| {
        CliError::setup(format!(
            "cannot create the directory {}: {e}",
            dir.display()
        ))
    })?;
    let written = write_man_pages(GobyCli::command().name(called_name()), dir).map_err(|e| {
        CliError::setup(format!(
            "cannot write the manual pages into {}: {e}",
            dir.display()
        ))
    })?;
    for path in written {
        writeln!(stdout, "{}", path.display())?;
    }
    Ok(Status::Ok)
}
