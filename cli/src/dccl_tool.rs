//! `goby dccl -e|-d|-a|-p ...`: the command line of the reference `dccl`
//! tool, so that a script written for it works with `goby dccl` in its place.
//!
//! - `-e`/`--encode`: text-format messages in (a line may start with
//!   `|full.Name|`), encoded messages out, raw bytes by default.
//! - `-d`/`--decode`: encoded messages in, raw bytes by default; each decoded
//!   message printed as `|full.Name| field: value ...` (`-o`: without the
//!   name).
//! - `-a`/`--analyze`: the size report of each type, or with `-H` only the
//!   definition hash (`full.Name: 0x...` when there are several types);
//!   `-w N` sets the width of the report's guard lines (60 by default).
//! - `-p`/`--display_proto`: the definition of each type as `.proto` source.
//!
//! Without `-m`, decode, analyze and display work on every valid DCCL type
//! of the `-f` files (each invalid one is named on standard error and
//! skipped), and encode takes the files' one type with a DCCL id for the
//! lines that do not name their type with `|full.Name|` (loaded only when
//! such a line comes); with several such types, a line without the prefix
//! is refused, naming them. As in the reference, a line whose
//! `|full.Name|` names another type than `-m` is encoded as the type it
//! names (`goby dccl encode -m` refuses such a line).
//!
//! Differences, on purpose: encode without `-m` never assumes a type the
//! files hold several candidates for, nor a helper message without a DCCL
//! id (the reference assumes the first message of the first file, whatever
//! it is); a bad input line is reported with its number
//! and the next lines are still handled (the reference stops at the first);
//! a file with no valid type is an error; base64 is written one message per
//! line (the reference's libb64 wraps at 72 characters; both are read); `-l`
//! (compiled message libraries) is not supported.

use std::io::{BufRead, Write};

use clap::{ArgGroup, Args};

use crate::dccl_cmd::{
    analyze, decode, encode, AnalyzeJob, ByteFormat, DecodeJob, Definitions, EncodeJob, InputForm,
    OutputForm, ProtoArgs, DEFAULT_CONSOLE_WIDTH,
};
use crate::passphrase::PassphraseArgs;
use crate::{CliError, Status};

/// First line of `--display_proto`, as the reference tool prints it.
const DISPLAY_NOTE: &str = "Please note that for Google Protobuf versions < 2.5.0, the dccl extensions will not be show below, so you'll need to refer to the original .proto file.";

/// The reference `dccl` tool's flags.
#[derive(Debug, Args)]
#[command(group(
    ArgGroup::new("action")
        .required(true)
        .args(["encode", "decode", "analyze", "display_proto"])
))]
pub struct ToolArgs {
    /// Encode text-format messages from standard input to standard output.
    #[arg(short = 'e', long = "encode")]
    pub encode: bool,
    /// Decode messages from standard input to standard output.
    #[arg(short = 'd', long = "decode")]
    pub decode: bool,
    /// Print the field sizes (or with -H the hash) of the message types.
    #[arg(short = 'a', long = "analyze")]
    pub analyze: bool,
    /// Print the definitions of the message types as .proto source.
    #[arg(short = 'p', long = "display_proto")]
    pub display_proto: bool,
    /// Message definitions.
    #[command(flatten)]
    pub proto: ProtoArgs,
    /// Message type to encode, decode, analyze or display (may be repeated
    /// except for encoding; decoding with one type decodes the bytes as that
    /// type, as `omit_id` types need).
    #[arg(short = 'm', long = "message", value_name = "FULL.Name")]
    pub message: Vec<String>,
    /// Form of the encoded messages written by -e and read by -d.
    #[arg(long, value_enum, default_value_t = ByteFormat::Bin)]
    pub format: ByteFormat,
    /// Omit the `|full.Name| ` prefix of decoded messages.
    #[arg(short = 'o', long = "omit_prefix")]
    pub omit_prefix: bool,
    /// With --analyze, print only the definition hash.
    #[arg(short = 'H', long = "hash_only")]
    pub hash_only: bool,
    /// With --analyze, the width in characters of the report's guard lines
    /// (`==== name ====`), 60 by default; accepted and unused otherwise, as
    /// by the reference tool.
    #[arg(
        short = 'w',
        long = "console_width",
        value_name = "N",
        default_value_t = DEFAULT_CONSOLE_WIDTH
    )]
    pub console_width: usize,
    /// Accepted for compatibility; prints nothing more.
    #[arg(short = 'v', long = "verbose")]
    pub verbose: bool,
    /// Not supported (compiled message libraries): give the `.proto` files with -f.
    #[arg(short = 'l', long = "dlopen", value_name = "LIB")]
    pub dlopen: Vec<String>,
    /// The DCCL id codec; only the default, `dccl.default.id`, is supported.
    #[arg(short = 'i', long = "id_codec", value_name = "NAME")]
    pub id_codec: Option<String>,
    /// Passphrase for encryption and decryption.
    #[command(flatten)]
    pub passphrase: PassphraseArgs,
    /// With --encode, refuse values out of their bounds instead of clamping
    /// or dropping them.
    #[arg(long)]
    pub strict: bool,
}

/// Runs `goby dccl` with the reference tool's flags.
pub fn run(
    args: &ToolArgs,
    stdin: &mut dyn BufRead,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    if let Some(lib) = args.dlopen.first() {
        return Err(CliError::setup(format!(
            "-l {lib}: loading compiled message libraries is not supported; give the .proto files with -f"
        )));
    }
    if let Some(id_codec) = args.id_codec.as_deref() {
        if id_codec != "dccl.default.id" {
            return Err(CliError::setup(format!(
                "-i {id_codec}: only the default id codec, dccl.default.id, is supported"
            )));
        }
    }
    let defs = Definitions::compile(&args.proto)?;
    if args.encode {
        let mut no_type = None;
        let (message, load_first) = match args.message.as_slice() {
            [] => match defs.dccl_types().as_slice() {
                [] => {
                    return Err(CliError::setup(format!(
                        "no message to encode: {} defines no message with a DCCL id \
                         ((dccl.msg) = {{ id: ... }}); give one with -m NAME",
                        defs.shown()
                    )))
                }
                [one] => {
                    writeln!(stderr, "Encoding assuming message: {one}")?;
                    (Some(one.clone()), false)
                }
                several => {
                    no_type = Some(format!(
                        "no message type: without -m a line must name its type with \
                         |full.Name|, as {} defines several DCCL types: {}",
                        defs.shown(),
                        several.join(", ")
                    ));
                    (None, false)
                }
            },
            [one] => (Some(one.clone()), true),
            _ => {
                return Err(CliError::setup(
                    "no more than one message type can be given with -m for encoding",
                ))
            }
        };
        let job = EncodeJob {
            message,
            load_first,
            no_type,
            input: InputForm::Text,
            format: args.format,
            passphrase: args.passphrase.resolve()?,
            strict: args.strict,
            // The reference tool encodes a line as the type its prefix
            // names, whatever -m gives.
            refuse_other_types: false,
        };
        encode(&defs, &job, stdin, stdout, stderr)
    } else if args.decode {
        let job = DecodeJob {
            messages: args.message.clone(),
            format: args.format,
            output: OutputForm::Text,
            prefix: !args.omit_prefix,
            passphrase: args.passphrase.resolve()?,
        };
        decode(&defs, &job, stdin, stdout, stderr)
    } else if args.analyze {
        let job = AnalyzeJob {
            hash_only: args.hash_only,
            console_width: args.console_width,
        };
        analyze(&defs, &args.message, &job, stdout, stderr)
    } else {
        display(&defs, &args.message, stdout, stderr)
    }
}

/// `--display_proto`: the definition of each valid type, sorted by name.
fn display(
    defs: &Definitions,
    names: &[String],
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    let mut codec = defs.new_codec(None, false)?;
    let names = if names.is_empty() {
        defs.load_valid(&mut codec, stderr)?
    } else {
        defs.load_named(&mut codec, names)?;
        let mut names = names.to_vec();
        names.sort();
        names.dedup();
        names
    };
    writeln!(stdout, "{DISPLAY_NOTE}")?;
    for name in &names {
        let desc = defs.message(name)?;
        stdout.write_all(crate::proto_display::message_definition(&desc).as_bytes())?;
    }
    Ok(Status::Ok)
}
