//! `goby dccl ...`: encode, decode, analyze and benchmark DCCL messages
//! defined in `.proto` files, with subcommands (`goby dccl encode ...`) or
//! with the flags of the reference `dccl` tool (`goby dccl -e ...`, see
//! [`crate::dccl_tool`]).

use std::collections::BTreeSet;
use std::fs;
use std::hint::black_box;
use std::io::{BufRead, Write};
use std::path::PathBuf;
use std::time::Instant;

use base64::engine::general_purpose::{GeneralPurpose, GeneralPurposeConfig};
use base64::engine::DecodePaddingMode;
use base64::Engine;
use clap::{Args, Subcommand, ValueEnum};
use dccl::Codec;
use prost_reflect::{
    DescriptorPool, DynamicMessage, MessageDescriptor, ReflectMessage, SerializeOptions,
};

use crate::byte_text;
use crate::dccl_tool::ToolArgs;
use crate::frame_decoder::{FrameDecoder, FrameError};
use crate::lines::{for_each_line, warn, LineError};
use crate::passphrase::PassphraseArgs;
use crate::{CliError, Status};

/// `goby dccl`: a subcommand, or the reference `dccl` tool's flags
/// (`-e`, `-d`, `-a`, `-p` with `-f`, `-I`, `-m`, `--format`, `-o`, `-H`, `-w`).
#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct DcclCli {
    /// The subcommand, when one is given.
    #[command(subcommand)]
    pub command: Option<DcclCommand>,
    /// The reference tool's flags, when no subcommand is given.
    #[command(flatten)]
    pub tool: ToolArgs,
}

/// Subcommands of `goby dccl`.
#[derive(Debug, Subcommand)]
pub enum DcclCommand {
    /// Encode messages read from standard input, one per line (protobuf text
    /// format or proto3 JSON; a line may start with `|full.Name|`, which must
    /// name the `-m` type); write one encoded message per line (or raw bytes with
    /// `--format bin`).
    Encode(EncodeArgs),
    /// Decode messages read from standard input, one or more per line (or raw
    /// bytes, messages back to back, with `--format bin`); each message's type
    /// is found by its DCCL id among the messages of the files, or given
    /// with `-m`.
    Decode(DecodeArgs),
    /// Print the size in bits of each field of message types (every valid
    /// type of the files without `-m`).
    Analyze(AnalyzeArgs),
    /// Time encoding and decoding of the messages read from standard input.
    Bench(BenchArgs),
    /// Write a Wireshark dissector (Lua) of the messages of the files.
    Wireshark(crate::wireshark::WiresharkArgs),
}

/// Where the message definitions come from.
#[derive(Debug, Args)]
pub struct ProtoArgs {
    /// A `.proto` file that defines the messages (may be repeated). Its own
    /// directory is searched for imports; `dccl/option_extensions.proto` is
    /// built in.
    #[arg(
        short = 'f',
        long = "file",
        visible_alias = "proto_file",
        value_name = "FILE.proto",
        required = true
    )]
    pub file: Vec<PathBuf>,
    /// A further directory to search for imports (may be repeated).
    #[arg(
        short = 'I',
        long = "include",
        visible_alias = "proto_path",
        value_name = "DIR"
    )]
    pub include: Vec<PathBuf>,
    /// Models of the arithmetic codec (`dccl.arithmetic`): one
    /// `dccl.arith.protobuf.ArithmeticModel` per line in protobuf text format.
    #[arg(long = "arithmetic-models", value_name = "FILE")]
    pub arithmetic_models: Option<PathBuf>,
}

/// Form of the messages read by `encode` and `bench`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum InputForm {
    /// Each line as it reads: proto3 JSON when it starts with `{` (a
    /// text-format message never does: it starts with a field name),
    /// otherwise protobuf text format.
    Auto,
    /// Protobuf text format, one message per line.
    Text,
    /// Proto3 JSON, one object per line.
    Json,
}

/// Form of the messages written by `decode`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OutputForm {
    /// Protobuf text format, one message per line.
    Text,
    /// Proto3 JSON (field names as in the `.proto`), one object per line.
    Json,
}

/// How encoded messages are written (by `encode`) or read (by `decode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ByteFormat {
    /// Lower-case hexadecimal, one line per message (on input, a line may
    /// hold several messages back to back).
    Hex,
    /// Standard base64, one line per message (as for hex, a line may hold
    /// several).
    Base64,
    /// A protobuf text-format byte string (`"\004\006"`), one line per message.
    Textformat,
    /// Raw bytes, messages back to back.
    Bin,
}

/// Arguments of `goby dccl encode`.
#[derive(Debug, Args)]
pub struct EncodeArgs {
    /// Message definitions.
    #[command(flatten)]
    pub proto: ProtoArgs,
    /// Full name of the message type to encode (e.g. `goby.example.NavigationReport`).
    #[arg(short = 'm', long = "message", value_name = "FULL.Name")]
    pub message: String,
    /// Form of the input messages.
    #[arg(long = "in", value_enum, default_value_t = InputForm::Auto)]
    pub input: InputForm,
    /// Form of the encoded output.
    #[arg(long, value_enum, default_value_t = ByteFormat::Hex)]
    pub format: ByteFormat,
    /// Passphrase for encryption.
    #[command(flatten)]
    pub passphrase: PassphraseArgs,
    /// Refuse values out of their bounds instead of clamping or dropping them.
    #[arg(long)]
    pub strict: bool,
}

/// Arguments of `goby dccl decode`.
#[derive(Debug, Args)]
pub struct DecodeArgs {
    /// Message definitions: every valid DCCL message of the files can be decoded.
    #[command(flatten)]
    pub proto: ProtoArgs,
    /// Decode as this type (needed for `omit_id` types); may be repeated, and
    /// then the types given are found by their ids.
    #[arg(short = 'm', long = "message", value_name = "FULL.Name")]
    pub message: Vec<String>,
    /// Form of the encoded input.
    #[arg(long, value_enum, default_value_t = ByteFormat::Hex)]
    pub format: ByteFormat,
    /// Form of the decoded output.
    #[arg(long = "out", value_enum, default_value_t = OutputForm::Text)]
    pub output: OutputForm,
    /// Passphrase for decryption.
    #[command(flatten)]
    pub passphrase: PassphraseArgs,
}

/// Arguments of `goby dccl analyze`.
#[derive(Debug, Args)]
pub struct AnalyzeArgs {
    /// Message definitions.
    #[command(flatten)]
    pub proto: ProtoArgs,
    /// Full name of a message type to analyze (may be repeated); without
    /// it, every valid DCCL type of the files, sorted by name (as the
    /// reference tool does).
    #[arg(short = 'm', long = "message", value_name = "FULL.Name")]
    pub message: Vec<String>,
    /// Print only the definition hash (`name: hash` lines when there are
    /// several types).
    #[arg(short = 'H', long = "hash-only", visible_alias = "hash_only")]
    pub hash_only: bool,
    /// Width in characters of the report's guard lines (`==== name ====`),
    /// 60 by default (the reference tool's `-w`).
    #[arg(
        short = 'w',
        long = "console-width",
        visible_alias = "console_width",
        value_name = "N",
        default_value_t = DEFAULT_CONSOLE_WIDTH
    )]
    pub console_width: usize,
}

/// Width of the guard lines of `analyze` unless `-w` gives another, as in libdccl.
pub const DEFAULT_CONSOLE_WIDTH: usize = 60;

/// Arguments of `goby dccl bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Message definitions.
    #[command(flatten)]
    pub proto: ProtoArgs,
    /// Full name of the message type of the input messages.
    #[arg(short = 'm', long = "message", value_name = "FULL.Name")]
    pub message: String,
    /// How many times to encode (and then decode) every input message.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub repeat: u64,
    /// Form of the input messages.
    #[arg(long = "in", value_enum, default_value_t = InputForm::Auto)]
    pub input: InputForm,
    /// Passphrase for encryption.
    #[command(flatten)]
    pub passphrase: PassphraseArgs,
}

/// Runs `goby dccl ...`.
pub fn run(
    cli: &DcclCli,
    stdin: &mut dyn BufRead,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    match &cli.command {
        Some(cmd) => run_command(cmd, stdin, stdout, stderr),
        None => crate::dccl_tool::run(&cli.tool, stdin, stdout, stderr),
    }
}

/// Runs a `goby dccl` subcommand.
pub fn run_command(
    cmd: &DcclCommand,
    stdin: &mut dyn BufRead,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    match cmd {
        DcclCommand::Encode(args) => {
            let defs = Definitions::compile(&args.proto)?;
            let job = EncodeJob {
                message: Some(args.message.clone()),
                load_first: true,
                input: args.input,
                format: args.format,
                passphrase: args.passphrase.resolve()?,
                strict: args.strict,
                refuse_other_types: true,
                no_type: None,
            };
            encode(&defs, &job, stdin, stdout, stderr)
        }
        DcclCommand::Decode(args) => {
            let defs = Definitions::compile(&args.proto)?;
            let job = DecodeJob {
                messages: args.message.clone(),
                format: args.format,
                output: args.output,
                prefix: false,
                passphrase: args.passphrase.resolve()?,
            };
            decode(&defs, &job, stdin, stdout, stderr)
        }
        DcclCommand::Analyze(args) => {
            let defs = Definitions::compile(&args.proto)?;
            let job = AnalyzeJob {
                hash_only: args.hash_only,
                console_width: args.console_width,
            };
            analyze(&defs, &args.message, &job, stdout, stderr)
        }
        DcclCommand::Bench(args) => bench(args, stdin, stdout, stderr),
        DcclCommand::Wireshark(args) => crate::wireshark::run(args, stdout, stderr),
    }
}

/// Compiled `.proto` files.
pub(crate) struct Definitions {
    pool: DescriptorPool,
    /// Names of the `-f` files inside the pool (relative to their include
    /// directory), in the order given.
    file_names: Vec<String>,
    /// The `-f` paths as given, for messages.
    shown: String,
    /// Text of the `--arithmetic-models` file.
    arithmetic_models: Option<String>,
}

impl Definitions {
    /// Compiles the `-f` files.
    pub(crate) fn compile(args: &ProtoArgs) -> Result<Self, CliError> {
        let mut shown = Vec::new();
        for file in &args.file {
            let name = file.display().to_string();
            if !file.exists() {
                return Err(CliError::setup(format!("{name}: no such file")));
            }
            if !file.is_file() {
                return Err(CliError::setup(format!("{name}: not a file")));
            }
            shown.push(name);
        }
        for dir in &args.include {
            if !dir.is_dir() {
                return Err(CliError::setup(format!(
                    "{}: include directory does not exist",
                    dir.display()
                )));
            }
        }
        let pool = dccl::compile_protos(args.file.as_slice(), args.include.as_slice())
            .map_err(|e| CliError::setup(e.to_string()))?;
        let mut file_names = Vec::new();
        for (file, name) in args.file.iter().zip(&shown) {
            let in_pool = dccl::pool_file_name(&pool, file, &args.include).ok_or_else(|| {
                CliError::setup(format!(
                    "{name}: compiled, but not found among the compiled files"
                ))
            })?;
            file_names.push(in_pool);
        }
        let arithmetic_models = match &args.arithmetic_models {
            None => None,
            Some(path) => {
                let text = fs::read_to_string(path).map_err(|e| {
                    CliError::setup(format!("{}: cannot read: {e}", path.display()))
                })?;
                // Checked now, so that a bad model file is reported as such.
                new_codec(None, false)
                    .load_arithmetic_models(&text)
                    .map_err(|e| CliError::setup(format!("{}: {e}", path.display())))?;
                Some(text)
            }
        };
        Ok(Definitions {
            pool,
            file_names,
            shown: shown.join(", "),
            arithmetic_models,
        })
    }

    /// A codec with the `--arithmetic-models` registered.
    pub(crate) fn new_codec(
        &self,
        passphrase: Option<&str>,
        strict: bool,
    ) -> Result<Codec, CliError> {
        let mut codec = new_codec(passphrase, strict);
        if let Some(text) = &self.arithmetic_models {
            codec
                .load_arithmetic_models(text)
                .map_err(|e| CliError::setup(e.to_string()))?;
        }
        Ok(codec)
    }

    /// Every message of the `-f` files, nested ones included, in declaration order.
    fn all_messages(&self) -> Vec<MessageDescriptor> {
        let mut out = Vec::new();
        for name in &self.file_names {
            if let Some(file) = self.pool.get_file_by_name(name) {
                let mut stack: Vec<MessageDescriptor> = file.messages().collect();
                stack.reverse();
                while let Some(m) = stack.pop() {
                    let mut children: Vec<MessageDescriptor> = m.child_messages().collect();
                    children.reverse();
                    stack.extend(children);
                    out.push(m);
                }
            }
        }
        out
    }

    /// The `-f` files as given, for messages.
    pub(crate) fn shown(&self) -> &str {
        &self.shown
    }

    /// Full names of the messages of the `-f` files (nested ones included,
    /// in declaration order) that have a DCCL id (`(dccl.msg) = { id: ... }`):
    /// the types that can be encoded on their own, helpers left out.
    pub(crate) fn dccl_types(&self) -> Vec<String> {
        self.all_messages()
            .into_iter()
            .filter(|m| {
                dccl::field::message_options(m)
                    .ok()
                    .is_some_and(|o| o.id.is_some())
            })
            .map(|m| m.full_name().to_string())
            .collect()
    }

    /// Descriptor of the message type `name`.
    pub(crate) fn message(&self, name: &str) -> Result<MessageDescriptor, CliError> {
        self.pool.get_message_by_name(name).ok_or_else(|| {
            let mut known: Vec<String> = self
                .all_messages()
                .iter()
                .map(|m| m.full_name().to_string())
                .collect();
            known.sort();
            let hint = if known.is_empty() {
                String::from("they define no message")
            } else {
                format!("they define: {}", known.join(", "))
            };
            CliError::setup(format!(
                "message type {name} is not defined in {} ({hint})",
                self.shown
            ))
        })
    }

    /// Loads the types `names` into `codec`; each must be valid.
    pub(crate) fn load_named(&self, codec: &mut Codec, names: &[String]) -> Result<(), CliError> {
        for name in names {
            let desc = self.message(name)?;
            codec
                .load(&desc)
                .map_err(|e| CliError::setup(format!("cannot load {name}: {e}")))?;
        }
        Ok(())
    }

    /// [`Definitions::load_named`], then the load warnings of the types on
    /// `stderr` (see [`write_load_warnings`]).
    pub(crate) fn load_named_warning(
        &self,
        codec: &mut Codec,
        names: &[String],
        stderr: &mut dyn Write,
    ) -> Result<(), CliError> {
        self.load_named(codec, names)?;
        write_load_warnings(codec, names, stderr)?;
        Ok(())
    }

    /// Loads every valid DCCL message of the files into `codec`, one type at
    /// a time (as the reference tool does: each top-level message and each
    /// nested one with a `(dccl.msg)` option); each type with a `(dccl.msg)`
    /// option that cannot be loaded is named on `stderr` with the reason and
    /// skipped (top-level messages without one are helpers, skipped quietly).
    /// Returns the names loaded, sorted. None is an error.
    pub(crate) fn load_valid(
        &self,
        codec: &mut Codec,
        stderr: &mut dyn Write,
    ) -> Result<Vec<String>, CliError> {
        let mut names = Vec::new();
        let mut meant_for_dccl = 0usize;
        for file in &self.file_names {
            let report = codec
                .load_valid_messages(&self.pool, file)
                .map_err(|e| CliError::setup(e.to_string()))?;
            meant_for_dccl += report.loaded.len();
            names.extend(report.loaded);
            for skipped in report.skipped {
                let has_options = self
                    .pool
                    .get_message_by_name(&skipped.name)
                    .is_some_and(|d| dccl::field::has_message_options(&d));
                if has_options {
                    meant_for_dccl += 1;
                    writeln!(
                        stderr,
                        "goby: warning: skipped {}, not a valid DCCL message: {}",
                        skipped.name, skipped.error
                    )?;
                }
            }
        }
        if meant_for_dccl == 0 {
            return Err(CliError::setup(format!(
                "{} defines no DCCL message (none has a (dccl.msg) option)",
                self.shown
            )));
        }
        if names.is_empty() {
            return Err(CliError::setup(format!(
                "{} defines no valid DCCL message",
                self.shown
            )));
        }
        names.sort();
        write_load_warnings(codec, &names, stderr)?;
        Ok(names)
    }
}

/// Writes on `stderr` what the review of the loaded types `names` found
/// (`goby: warning: TYPE.FIELD: dynamic_conditions.KIND "SCRIPT" ...`):
/// conditions that change nothing, scripts naming no field, scripts reading
/// a field a receiver has not decoded yet.
pub(crate) fn write_load_warnings(
    codec: &Codec,
    names: &[String],
    stderr: &mut dyn Write,
) -> std::io::Result<()> {
    for name in names {
        for warning in codec.load_warnings(name).unwrap_or_default() {
            writeln!(stderr, "goby: warning: {warning}")?;
        }
    }
    Ok(())
}

fn new_codec(passphrase: Option<&str>, strict: bool) -> Codec {
    let mut codec = Codec::new();
    codec.set_strict(strict);
    if let Some(p) = passphrase {
        codec.set_passphrase(p);
    }
    codec
}

/// Parses one input message.
fn parse_message(
    desc: &MessageDescriptor,
    form: InputForm,
    line: &str,
) -> Result<DynamicMessage, String> {
    let json_like = line.trim_start().starts_with('{');
    let form = match form {
        InputForm::Auto if json_like => InputForm::Json,
        InputForm::Auto => InputForm::Text,
        given => given,
    };
    match form {
        InputForm::Text | InputForm::Auto => DynamicMessage::parse_text_format(desc.clone(), line)
            .map_err(|e| {
                let hint = if json_like {
                    " (the line starts with '{' as JSON does: leave out --in text, or give --in json)"
                } else {
                    ""
                };
                format!("cannot parse as text format {}: {e}{hint}", desc.full_name())
            }),
        InputForm::Json => {
            let mut de = serde_json::Deserializer::from_str(line);
            let msg = DynamicMessage::deserialize(desc.clone(), &mut de)
                .and_then(|m| de.end().map(|()| m))
                .map_err(|e| format!("cannot parse as JSON {}: {e}", desc.full_name()))?;
            Ok(msg)
        }
    }
}

/// Formats one decoded message on one line; `prefix` puts `|full.Name| `
/// before the text form, as the reference tool prints it.
fn format_message(msg: &DynamicMessage, form: OutputForm, prefix: bool) -> Result<String, String> {
    match form {
        OutputForm::Text => {
            let text = dccl::short_debug_string(msg);
            if prefix {
                Ok(format!("|{}| {text}", msg.descriptor().full_name()))
            } else {
                Ok(text)
            }
        }
        OutputForm::Json => {
            let mut buf = Vec::new();
            let mut ser = serde_json::Serializer::new(&mut buf);
            msg.serialize_with_options(
                &mut ser,
                &SerializeOptions::new().use_proto_field_name(true),
            )
            .map_err(|e| format!("cannot write as JSON: {e}"))?;
            String::from_utf8(buf).map_err(|e| format!("cannot write as JSON: {e}"))
        }
    }
}

/// Length of a full line of base64 as libb64 (the reference tool's base64
/// library) wraps its output.
const BASE64_WRAP: usize = 72;

fn base64_engine() -> GeneralPurpose {
    GeneralPurpose::new(
        &base64::alphabet::STANDARD,
        GeneralPurposeConfig::new().with_decode_padding_mode(DecodePaddingMode::Indifferent),
    )
}

/// What `encode` does, however it was asked for.
pub(crate) struct EncodeJob {
    /// Type of the lines that do not start with `|full.Name|`.
    pub message: Option<String>,
    /// Load `message` before reading any line, so that an invalid type stops
    /// the command; otherwise it is loaded by the first line without
    /// `|full.Name|`, and a line that names its type never needs it (the
    /// reference tool's type assumed from the file without `-m`).
    pub load_first: bool,
    /// Form of the input lines.
    pub input: InputForm,
    /// Form of the output.
    pub format: ByteFormat,
    /// Passphrase for encryption.
    pub passphrase: Option<String>,
    /// Refuse the values the codec would change.
    pub strict: bool,
    /// Refuse a line whose `|full.Name|` prefix names a type other than
    /// `message` (`goby dccl encode -m`); otherwise such a line is encoded as
    /// the type it names, as the reference tool does.
    pub refuse_other_types: bool,
    /// Why a line without `|full.Name|` has no type when `message` is
    /// `None` (e.g. the candidates to choose from).
    pub no_type: Option<String>,
}

/// Splits a leading `|full.Name|` (the reference tool's way of giving the
/// type on the line) from the message text.
fn split_type_prefix(line: &str) -> Result<(Option<&str>, &str), String> {
    match line.strip_prefix('|') {
        None => Ok((None, line)),
        Some(rest) => match rest.split_once('|') {
            Some((name, text)) => Ok((Some(name.trim()), text.trim())),
            None => Err("a line starting with '|' must name its type as |full.Name|".into()),
        },
    }
}

/// Warnings for the times (fields with the `dccl.time` codec) of `sent` that
/// decode from `bytes` to another value on this machine: the codec sends
/// the time of day only, and the receiver puts it within 12 hours of its
/// own clock, so a time further than that from the clock comes back on
/// another day.
pub(crate) fn moved_times(codec: &Codec, sent: &DynamicMessage, bytes: &[u8]) -> Vec<String> {
    let descriptor = sent.descriptor();
    let name = descriptor.full_name();
    moved_time_fields(codec, sent, bytes)
        .into_iter()
        .map(|(path, sent, back)| {
            format!(
                "{name}.{path}: {sent} is more than 12 hours from this machine's clock: \
                 the time codec sends the time of day only, and it decodes as {back}: \
                 that time of day within 12 hours of the receiver's clock"
            )
        })
        .collect()
}

/// The times of `sent` that [`moved_times`] warns of: (field path, value
/// sent, value decoded), each value with its UTC date.
pub(crate) fn moved_time_fields(
    codec: &Codec,
    sent: &DynamicMessage,
    bytes: &[u8],
) -> Vec<(String, String, String)> {
    let name = sent.descriptor().full_name().to_string();
    let has_time = sent.descriptor().fields().any(|f| {
        dccl::field::field_options(&f)
            .ok()
            .and_then(|o| o.codec)
            .is_some_and(|c| c.starts_with("dccl.time"))
            || matches!(f.kind(), prost_reflect::Kind::Message(_))
    });
    if !has_time {
        return Vec::new();
    }
    let Ok(dccl::Decoded { message: back, .. }) =
        codec.decode_with(bytes, &dccl::DecodeOptions::as_type(&name))
    else {
        return Vec::new();
    };
    let mut moved = Vec::new();
    collect_moved_times("", sent, &back, &mut moved);
    moved
}

/// `YYYY-MM-DD HH:MM:SS UTC` of seconds since the epoch.
fn utc_date(secs: u64) -> String {
    let (y, mo, d, h, mi, s) = goby_time::civil(secs);
    format!("{y:04}-{mo:02}-{d:02} {h:02}:{mi:02}:{s:02} UTC")
}

/// Adds to `out` (field path, sent, decoded) for each `dccl.time` field of
/// `sent` (nested messages included, repeated fields not) that `back` has
/// with another value.
fn collect_moved_times(
    prefix: &str,
    sent: &DynamicMessage,
    back: &DynamicMessage,
    out: &mut Vec<(String, String, String)>,
) {
    for field in sent.descriptor().fields() {
        if field.is_list() || !sent.has_field(&field) {
            continue;
        }
        let path = format!("{prefix}{}", field.name());
        let (a, b) = (sent.get_field(&field), back.get_field(&field));
        if let (Some(a), Some(b)) = (a.as_message(), b.as_message()) {
            collect_moved_times(&format!("{path}."), a, b, out);
            continue;
        }
        let is_time = dccl::field::field_options(&field)
            .ok()
            .and_then(|o| o.codec)
            .is_some_and(|c| c.starts_with("dccl.time"));
        // Seconds (double fields) or microseconds (64-bit integer fields);
        // a difference under 12 hours is the codec's rounding to its precision.
        let seconds = |v: &prost_reflect::Value| match v {
            prost_reflect::Value::F64(x) => Some(*x),
            prost_reflect::Value::I64(x) => Some(*x as f64 / 1e6),
            prost_reflect::Value::U64(x) => Some(*x as f64 / 1e6),
            _ => None,
        };
        let moved = match (seconds(&a), seconds(&b)) {
            (Some(x), Some(y)) => (x - y).abs() >= 43_200.0,
            _ => false,
        };
        if is_time && moved {
            // The value as given, with its UTC date for the reader.
            let text = |v: &prost_reflect::Value| {
                let raw = match v {
                    prost_reflect::Value::F64(x) => x.to_string(),
                    prost_reflect::Value::I64(x) => x.to_string(),
                    prost_reflect::Value::U64(x) => x.to_string(),
                    other => format!("{other:?}"),
                };
                match seconds(v).filter(|s| *s >= 0.0 && s.is_finite()) {
                    Some(s) => format!("{raw} ({})", utc_date(s as u64)),
                    None => raw,
                }
            };
            out.push((path, text(&a), text(&b)));
        }
    }
}

/// `goby dccl encode` / `goby dccl -e`.
pub(crate) fn encode(
    defs: &Definitions,
    job: &EncodeJob,
    stdin: &mut dyn BufRead,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    let mut codec = defs.new_codec(job.passphrase.as_deref(), job.strict)?;
    if let (Some(name), true) = (&job.message, job.load_first) {
        defs.load_named_warning(&mut codec, std::slice::from_ref(name), stderr)?;
    }
    let engine = base64_engine();
    let bad = for_each_line(stdin, stderr, |number, line, stderr| {
        let (named, text) = split_type_prefix(line).map_err(LineError::Bad)?;
        if let (true, Some(named), Some(given)) =
            (job.refuse_other_types, named, job.message.as_deref())
        {
            if named != given {
                return Err(LineError::Bad(format!(
                    "the line is prefixed |{named}| but -m gives {given}: \
                     remove the prefix, or encode {named} lines with -m {named}"
                )));
            }
        }
        let name = match named.or(job.message.as_deref()) {
            Some(name) => name,
            None => {
                return Err(LineError::Bad(job.no_type.clone().unwrap_or_else(|| {
                    "no message type: give -m NAME or start the line with |full.Name|".into()
                })))
            }
        };
        let desc = match codec.descriptor(name) {
            Some(desc) => desc,
            None => {
                let desc = defs
                    .message(name)
                    .map_err(|e| LineError::Bad(e.to_string()))?;
                codec
                    .load(&desc)
                    .map_err(|e| LineError::Bad(format!("cannot load {name}: {e}")))?;
                write_load_warnings(&codec, &[name.to_string()], stderr)?;
                desc
            }
        };
        let msg = parse_message(&desc, job.input, text).map_err(LineError::Bad)?;
        // As gobyd checks what it sends: does a receiver decode the frame
        // as it is encoded? (libdccl writes the same bytes either way.) A
        // message the codec refuses is refused by the encoding below.
        let not_as_encoded = codec
            .round_trip(&msg)
            .ok()
            .flatten()
            .map(|why| format!("{name}: the frame does not decode as it was encoded: {why}"));
        if let (true, Some(why)) = (job.strict, &not_as_encoded) {
            return Err(LineError::Bad(format!("cannot encode: {why}")));
        }
        let mut bytes = Vec::new();
        let changes = codec
            .encode_with(&msg, &mut bytes, &dccl::EncodeOptions::with_changes())
            .map_err(|e| LineError::Bad(e.to_string()))?
            .changes;
        for change in &changes {
            let warning = format!("{}.{}: {}", change.message, change.field, change.reason);
            warn(stderr, number, &warning)?;
        }
        if let Some(why) = &not_as_encoded {
            warn(stderr, number, why)?;
        }
        for warning in moved_times(&codec, &msg, &bytes) {
            warn(stderr, number, &warning)?;
        }
        match job.format {
            ByteFormat::Hex => writeln!(stdout, "{}", hex::encode(&bytes))?,
            ByteFormat::Base64 => writeln!(stdout, "{}", engine.encode(&bytes))?,
            ByteFormat::Textformat => writeln!(stdout, "{}", byte_text::escape(&bytes))?,
            ByteFormat::Bin => stdout.write_all(&bytes)?,
        }
        stdout.flush()?;
        Ok(())
    })?;
    Ok(Status::from_bad_count(bad))
}

/// What `decode` does, however it was asked for.
pub(crate) struct DecodeJob {
    /// The types to decode (`-m`): none, every valid type of the files; one,
    /// the bytes are decoded as that type; several, found by their ids.
    pub messages: Vec<String>,
    /// Form of the input.
    pub format: ByteFormat,
    /// Form of the output.
    pub output: OutputForm,
    /// Put `|full.Name| ` before each text line.
    pub prefix: bool,
    /// Passphrase for decryption.
    pub passphrase: Option<String>,
}

/// `goby dccl decode` / `goby dccl -d`.
pub(crate) fn decode(
    defs: &Definitions,
    job: &DecodeJob,
    stdin: &mut dyn BufRead,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    let mut codec = defs.new_codec(job.passphrase.as_deref(), false)?;
    if job.messages.is_empty() {
        defs.load_valid(&mut codec, stderr)?;
    } else {
        defs.load_named_warning(&mut codec, &job.messages, stderr)?;
    }
    let decoder = FrameDecoder {
        codec: &codec,
        as_type: match job.messages.as_slice() {
            [one] => Some(one.as_str()),
            _ => None,
        },
        encrypted: job.passphrase.is_some(),
    };
    let emit = |stdout: &mut dyn Write, msg: &DynamicMessage| -> Result<(), LineError> {
        let text = format_message(msg, job.output, job.prefix).map_err(LineError::Bad)?;
        writeln!(stdout, "{text}")?;
        Ok(())
    };
    if job.format == ByteFormat::Bin {
        let mut bytes = Vec::new();
        stdin.read_to_end(&mut bytes).map_err(CliError::Input)?;
        return match decoder.decode(&bytes, |m| emit(stdout, m)) {
            Ok(()) => Ok(Status::Ok),
            Err(FrameError::Output(LineError::Fatal(e))) => Err(e),
            Err(e) => {
                writeln!(stderr, "{}", e.describe())?;
                Ok(Status::BadInput(1))
            }
        };
    }
    let engine = base64_engine();
    // The start of a message continued on the next line: (its line, its bytes).
    let mut pending: Option<(usize, Vec<u8>)> = None;
    let mut bad = for_each_line(stdin, stderr, |number, line, _| {
        let decoded = match job.format {
            ByteFormat::Hex => {
                hex::decode(line).map_err(|e| LineError::Bad(format!("not valid hex: {e}")))?
            }
            ByteFormat::Base64 => engine
                .decode(line)
                .map_err(|e| LineError::Bad(format!("not valid base64: {e}")))?,
            ByteFormat::Textformat | ByteFormat::Bin => byte_text::unescape(line)
                .map_err(|e| LineError::Bad(format!("not a text-format byte string: {e}")))?,
        };
        let (first_line, bytes) = match pending.take() {
            Some((first, mut bytes)) => {
                bytes.extend_from_slice(&decoded);
                (first, bytes)
            }
            None => (number, decoded),
        };
        let result = decoder.decode(&bytes, |m| emit(stdout, m));
        stdout.flush()?;
        match result {
            Ok(()) => Ok(()),
            // A full line of wrapped base64 (as libb64 writes messages over 54
            // bytes) that ends inside a message: the message goes on.
            Err(FrameError::Bad {
                offset, truncated, ..
            }) if truncated && job.format == ByteFormat::Base64 && line.len() == BASE64_WRAP => {
                pending = Some((first_line, bytes[offset..].to_vec()));
                Ok(())
            }
            Err(FrameError::Output(e)) => Err(e),
            Err(e) => {
                let continued = if first_line == number {
                    String::new()
                } else {
                    format!(" (continued from line {first_line})")
                };
                Err(LineError::Bad(format!("{}{continued}", e.describe())))
            }
        }
    })?;
    if let Some((first_line, bytes)) = pending {
        bad += 1;
        writeln!(
            stderr,
            "line {first_line}: the input ends inside a message ({} byte(s) left undecoded)",
            bytes.len()
        )?;
    }
    Ok(Status::from_bad_count(bad))
}

/// How `analyze` reports, however it was asked for.
pub(crate) struct AnalyzeJob {
    /// Print only the definition hash of each type.
    pub hash_only: bool,
    /// Width of the report's guard lines.
    pub console_width: usize,
}

/// `goby dccl analyze` / `goby dccl -a`: the size report of each type, or
/// with `hash_only` its definition hash (`name: hash` when there are several).
pub(crate) fn analyze(
    defs: &Definitions,
    names: &[String],
    job: &AnalyzeJob,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    let mut codec = defs.new_codec(None, false)?;
    let names: Vec<String> = if names.is_empty() {
        defs.load_valid(&mut codec, stderr)?
    } else {
        defs.load_named_warning(&mut codec, names, stderr)?;
        names
            .iter()
            .cloned()
            .collect::<BTreeSet<String>>()
            .into_iter()
            .collect()
    };
    for name in &names {
        if job.hash_only {
            let hash = codec
                .hash(name)
                .map_err(|e| CliError::setup(e.to_string()))?;
            let hash = format!("{hash:#018x}"); // as libdccl prints it
            if names.len() > 1 {
                writeln!(stdout, "{name}: {hash}")?;
            } else {
                writeln!(stdout, "{hash}")?;
            }
        } else {
            let report = codec
                .analyze_with_width(name, job.console_width)
                .map_err(|e| CliError::setup(e.to_string()))?;
            stdout.write_all(report.as_bytes())?;
            if !report.ends_with('\n') {
                writeln!(stdout)?;
            }
        }
    }
    Ok(Status::Ok)
}

/// `goby dccl bench`.
fn bench(
    args: &BenchArgs,
    stdin: &mut dyn BufRead,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    let defs = Definitions::compile(&args.proto)?;
    let passphrase = args.passphrase.resolve()?;
    let mut codec = defs.new_codec(passphrase.as_deref(), false)?;
    defs.load_named_warning(&mut codec, std::slice::from_ref(&args.message), stderr)?;
    let desc = defs.message(&args.message)?;

    let mut messages = Vec::new();
    let mut encoded = Vec::new();
    let bad = for_each_line(stdin, stderr, |_, line, _| {
        let msg = parse_message(&desc, args.input, line).map_err(LineError::Bad)?;
        let bytes = codec
            .encode(&msg)
            .map_err(|e| LineError::Bad(e.to_string()))?;
        codec
            .decode(&bytes)
            .map_err(|e| LineError::Bad(format!("cannot decode its own encoding: {e}")))?;
        messages.push(msg);
        encoded.push(bytes);
        Ok(())
    })?;
    if messages.is_empty() {
        writeln!(stderr, "goby: error: no message to time on standard input")?;
        return Ok(Status::BadInput(bad.max(1)));
    }

    let count = messages.len() as f64;
    let rounds = args.repeat as f64;

    let start = Instant::now();
    for _ in 0..args.repeat {
        for msg in &messages {
            let _ = black_box(codec.encode(black_box(msg)));
        }
    }
    let encode_ns = start.elapsed().as_nanos() as f64 / (rounds * count);

    let start = Instant::now();
    for _ in 0..args.repeat {
        for bytes in &encoded {
            let _ = black_box(codec.decode(black_box(bytes.as_slice())));
        }
    }
    let decode_ns = start.elapsed().as_nanos() as f64 / (rounds * count);

    let round = |x: f64| serde_json::Value::from((x * 10.0).round() / 10.0);
    writeln!(
        stdout,
        "{{\"messages\":{},\"encode_ns_per_msg\":{},\"decode_ns_per_msg\":{}}}",
        messages.len(),
        round(encode_ns),
        round(decode_ns)
    )?;
    Ok(Status::from_bad_count(bad))
}
