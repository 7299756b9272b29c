//! `goby dccl ...`: encode, decode, analyze and benchmark DCCL messages
//! defined in `.proto` files.

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
use prost_reflect::{DescriptorPool, DynamicMessage, MessageDescriptor, SerializeOptions};

use crate::lines::{for_each_line, LineError};
use crate::{CliError, Status};

/// Subcommands of `goby dccl`.
#[derive(Debug, Subcommand)]
pub enum DcclCommand {
    /// Encode messages read from standard input, one per line (protobuf text
    /// format or proto3 JSON); write one encoded message per line (or raw
    /// bytes with `--format bin`).
    Encode(EncodeArgs),
    /// Decode messages read from standard input, one per line (or raw bytes,
    /// possibly several messages back to back, with `--format bin`); each
    /// message's type is found by its DCCL id among the messages of the file.
    Decode(DecodeArgs),
    /// Print the size in bits of each field of a message type.
    Analyze(AnalyzeArgs),
    /// Time encoding and decoding of the messages read from standard input.
    Bench(BenchArgs),
}

/// Where the message definitions come from.
#[derive(Debug, Args)]
pub struct ProtoArgs {
    /// The `.proto` file that defines the messages. Its own directory is
    /// searched for imports; `dccl/option_extensions.proto` is built in.
    #[arg(short = 'f', long = "file", value_name = "FILE.proto")]
    pub file: PathBuf,
    /// A further directory to search for imports (may be repeated).
    #[arg(short = 'I', long = "include", value_name = "DIR")]
    pub include: Vec<PathBuf>,
    /// Models of the arithmetic codec (`dccl.arithmetic`): one
    /// `dccl.arith.protobuf.ArithmeticModel` per line in protobuf text format.
    #[arg(long = "arithmetic-models", value_name = "FILE")]
    pub arithmetic_models: Option<PathBuf>,
}

/// Form of the messages read by `encode` and `bench`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum InputForm {
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
    /// Lower-case hexadecimal, one message per line.
    Hex,
    /// Standard base64, one message per line.
    Base64,
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
    #[arg(long = "in", value_enum, default_value_t = InputForm::Text)]
    pub input: InputForm,
    /// Form of the encoded output.
    #[arg(long, value_enum, default_value_t = ByteFormat::Hex)]
    pub format: ByteFormat,
    /// Encrypt message bodies with this passphrase (key = SHA-256 of it).
    #[arg(long, value_name = "P")]
    pub passphrase: Option<String>,
    /// Refuse values out of their bounds instead of clamping or dropping them.
    #[arg(long)]
    pub strict: bool,
}

/// Arguments of `goby dccl decode`.
#[derive(Debug, Args)]
pub struct DecodeArgs {
    /// Message definitions: every DCCL message of the file can be decoded.
    #[command(flatten)]
    pub proto: ProtoArgs,
    /// Form of the encoded input.
    #[arg(long, value_enum, default_value_t = ByteFormat::Hex)]
    pub format: ByteFormat,
    /// Form of the decoded output.
    #[arg(long = "out", value_enum, default_value_t = OutputForm::Text)]
    pub output: OutputForm,
    /// Decrypt message bodies with this passphrase (key = SHA-256 of it).
    #[arg(long, value_name = "P")]
    pub passphrase: Option<String>,
}

/// Arguments of `goby dccl analyze`.
#[derive(Debug, Args)]
pub struct AnalyzeArgs {
    /// Message definitions.
    #[command(flatten)]
    pub proto: ProtoArgs,
    /// Full name of the message type to analyze.
    #[arg(short = 'm', long = "message", value_name = "FULL.Name")]
    pub message: String,
}

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
    #[arg(long = "in", value_enum, default_value_t = InputForm::Text)]
    pub input: InputForm,
    /// Encrypt message bodies with this passphrase (key = SHA-256 of it).
    #[arg(long, value_name = "P")]
    pub passphrase: Option<String>,
}

/// Runs a `goby dccl` subcommand.
pub fn run(
    cmd: &DcclCommand,
    stdin: &mut dyn BufRead,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    match cmd {
        DcclCommand::Encode(args) => encode(args, stdin, stdout, stderr),
        DcclCommand::Decode(args) => decode(args, stdin, stdout, stderr),
        DcclCommand::Analyze(args) => analyze(args, stdout),
        DcclCommand::Bench(args) => bench(args, stdin, stdout, stderr),
    }
}

/// A compiled `.proto` file.
struct Definitions {
    pool: DescriptorPool,
    /// Name of the `-f` file inside the pool (relative to its include directory).
    file_name: String,
    /// The `-f` path as given, for messages.
    shown: String,
    /// Text of the `--arithmetic-models` file.
    arithmetic_models: Option<String>,
}

impl Definitions {
    /// Compiles the `-f` file.
    fn compile(args: &ProtoArgs) -> Result<Self, CliError> {
        let shown = args.file.display().to_string();
        if !args.file.exists() {
            return Err(CliError::setup(format!("{shown}: no such file")));
        }
        if !args.file.is_file() {
            return Err(CliError::setup(format!("{shown}: not a file")));
        }
        for dir in &args.include {
            if !dir.is_dir() {
                return Err(CliError::setup(format!(
                    "{}: include directory does not exist",
                    dir.display()
                )));
            }
        }
        let pool = dccl::compile_protos(std::slice::from_ref(&args.file), args.include.as_slice())
            .map_err(|e| CliError::setup(e.to_string()))?;
        let file_name =
            dccl::pool_file_name(&pool, &args.file, &args.include).ok_or_else(|| {
                CliError::setup(format!(
                    "{shown}: compiled, but not found among the compiled files"
                ))
            })?;
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
            file_name,
            shown,
            arithmetic_models,
        })
    }

    /// A codec with the `--arithmetic-models` registered.
    fn new_codec(&self, passphrase: Option<&str>, strict: bool) -> Result<Codec, CliError> {
        let mut codec = new_codec(passphrase, strict);
        if let Some(text) = &self.arithmetic_models {
            codec
                .load_arithmetic_models(text)
                .map_err(|e| CliError::setup(e.to_string()))?;
        }
        Ok(codec)
    }

    /// Descriptor of the message type `name`.
    fn message(&self, name: &str) -> Result<MessageDescriptor, CliError> {
        self.pool.get_message_by_name(name).ok_or_else(|| {
            let mut known = Vec::new();
            if let Some(file) = self.pool.get_file_by_name(&self.file_name) {
                let mut stack: Vec<MessageDescriptor> = file.messages().collect();
                while let Some(m) = stack.pop() {
                    stack.extend(m.child_messages());
                    known.push(m.full_name().to_string());
                }
            }
            known.sort();
            let hint = if known.is_empty() {
                String::from("it defines no message")
            } else {
                format!("it defines: {}", known.join(", "))
            };
            CliError::setup(format!(
                "message type {name} is not defined in {} ({hint})",
                self.shown
            ))
        })
    }

    /// A codec with the message type `name` loaded.
    fn codec_for(
        &self,
        name: &str,
        passphrase: Option<&str>,
        strict: bool,
    ) -> Result<(Codec, MessageDescriptor), CliError> {
        let desc = self.message(name)?;
        let mut codec = self.new_codec(passphrase, strict)?;
        codec
            .load(&desc)
            .map_err(|e| CliError::setup(format!("cannot load {name}: {e}")))?;
        Ok((codec, desc))
    }
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
    match form {
        InputForm::Text => DynamicMessage::parse_text_format(desc.clone(), line)
            .map_err(|e| format!("cannot parse as text format {}: {e}", desc.full_name())),
        InputForm::Json => {
            let mut de = serde_json::Deserializer::from_str(line);
            let msg = DynamicMessage::deserialize(desc.clone(), &mut de)
                .and_then(|m| de.end().map(|()| m))
                .map_err(|e| format!("cannot parse as JSON {}: {e}", desc.full_name()))?;
            Ok(msg)
        }
    }
}

/// Formats one decoded message on one line.
fn format_message(msg: &DynamicMessage, form: OutputForm) -> Result<String, String> {
    match form {
        OutputForm::Text => Ok(dccl::text_format::short_debug_string(msg)),
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

fn base64_engine() -> GeneralPurpose {
    GeneralPurpose::new(
        &base64::alphabet::STANDARD,
        GeneralPurposeConfig::new().with_decode_padding_mode(DecodePaddingMode::Indifferent),
    )
}

/// `goby dccl encode`.
fn encode(
    args: &EncodeArgs,
    stdin: &mut dyn BufRead,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    let defs = Definitions::compile(&args.proto)?;
    let (codec, desc) = defs.codec_for(&args.message, args.passphrase.as_deref(), args.strict)?;
    let engine = base64_engine();
    let bad = for_each_line(stdin, stderr, |_, line| {
        let msg = parse_message(&desc, args.input, line).map_err(LineError::Bad)?;
        let bytes = codec
            .encode(&msg)
            .map_err(|e| LineError::Bad(e.to_string()))?;
        match args.format {
            ByteFormat::Hex => writeln!(stdout, "{}", hex::encode(&bytes))?,
            ByteFormat::Base64 => writeln!(stdout, "{}", engine.encode(&bytes))?,
            ByteFormat::Bin => stdout.write_all(&bytes)?,
        }
        stdout.flush()?;
        Ok(())
    })?;
    Ok(Status::from_bad_count(bad))
}

/// `goby dccl decode`.
fn decode(
    args: &DecodeArgs,
    stdin: &mut dyn BufRead,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    let defs = Definitions::compile(&args.proto)?;
    let mut codec = defs.new_codec(args.passphrase.as_deref(), false)?;
    let names = codec
        .load_file_messages(&defs.pool, &defs.file_name)
        .map_err(|e| CliError::setup(format!("cannot load the messages of {}: {e}", defs.shown)))?;
    if names.is_empty() {
        return Err(CliError::setup(format!(
            "{} defines no DCCL message (none has a (dccl.msg) option)",
            defs.shown
        )));
    }
    if args.format == ByteFormat::Bin {
        return decode_stream(&codec, args.output, stdin, stdout, stderr);
    }
    let engine = base64_engine();
    let bad = for_each_line(stdin, stderr, |_, line| {
        let bytes = match args.format {
            ByteFormat::Hex => {
                hex::decode(line).map_err(|e| LineError::Bad(format!("not valid hex: {e}")))?
            }
            _ => engine
                .decode(line)
                .map_err(|e| LineError::Bad(format!("not valid base64: {e}")))?,
        };
        let msg = codec
            .decode(&bytes)
            .map_err(|e| LineError::Bad(e.to_string()))?;
        let text = format_message(&msg, args.output).map_err(LineError::Bad)?;
        writeln!(stdout, "{text}")?;
        stdout.flush()?;
        Ok(())
    })?;
    Ok(Status::from_bad_count(bad))
}

/// `goby dccl decode --format bin`: all of the input is one byte string
/// holding one or more messages back to back.
fn decode_stream(
    codec: &Codec,
    form: OutputForm,
    stdin: &mut dyn BufRead,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    let mut bytes = Vec::new();
    stdin.read_to_end(&mut bytes).map_err(CliError::Input)?;
    let mut offset = 0usize;
    let mut bad = 0usize;
    while offset < bytes.len() {
        match codec.decode_prefix(&bytes[offset..]) {
            Ok((msg, used)) => {
                match format_message(&msg, form) {
                    Ok(text) => writeln!(stdout, "{text}")?,
                    Err(e) => {
                        bad += 1;
                        writeln!(stderr, "byte {offset}: {e}")?;
                    }
                }
                if used == 0 {
                    break;
                }
                offset += used;
            }
            Err(e) => {
                // Without a message length there is no way to find the next one.
                bad += 1;
                writeln!(
                    stderr,
                    "byte {offset}: {e} ({} byte(s) left undecoded)",
                    bytes.len() - offset
                )?;
                break;
            }
        }
    }
    Ok(Status::from_bad_count(bad))
}

/// `goby dccl analyze`.
fn analyze(args: &AnalyzeArgs, stdout: &mut dyn Write) -> Result<Status, CliError> {
    let defs = Definitions::compile(&args.proto)?;
    let (codec, desc) = defs.codec_for(&args.message, None, false)?;
    let report = codec
        .analyze(desc.full_name())
        .map_err(|e| CliError::setup(e.to_string()))?;
    stdout.write_all(report.as_bytes())?;
    if !report.ends_with('\n') {
        writeln!(stdout)?;
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
    let (codec, desc) = defs.codec_for(&args.message, args.passphrase.as_deref(), false)?;

    let mut messages = Vec::new();
    let mut encoded = Vec::new();
    let bad = for_each_line(stdin, stderr, |_, line| {
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
